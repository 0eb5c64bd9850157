"""The verdict rule shared by every plant's diagnosis: none, an effect, or unexplained."""

from __future__ import annotations

__all__ = ["decide_verdict"]


def decide_verdict(significant: list, fits: list, explains, joint_wins: bool, gap_is_real: bool) \
        -> tuple[str, object, list]:
    """The verdict rule shared by every plant's diagnosis (docs/contracts.md: none / an effect / unexplained).

    The best significant candidate that explains the gap on its own is the verdict; if none does, the best one is
    the verdict when fitting it together with the second one does (two effects at once: the larger is the verdict,
    the other follows in candidates). A real gap that no candidate explains is ``unexplained``; otherwise ``none``.

    A candidate that closes the gap alone comes before a better-ranked one that needs a partner: on a log with a
    radius error and a relaxation length (combos seed 3903, log 37), a friction change ranked first by its held-out
    error (it fits a few lock-up windows) left 84 % of the robust gap, the radius error alone none of it.

    :param significant: the significant candidates, best first.
    :param fits: all candidates, best first.
    :param explains: ``fit -> bool``, whether a fit closes a clear share of the gap on held-out data.
    :param joint_wins: whether the joint fit of the two best is significant, explains, and beats the best alone.
    :param gap_is_real: whether the nominal model does not fit within the noise (its held-out gap is large, or a
        candidate beats it significantly on held-out data).
    :return: (verdict, chosen fit or None, candidates with the chosen one first).
    """
    alone = next((f for f in significant if explains(f)), None)
    if alone is not None or (significant and joint_wins):
        chosen = alone if alone is not None else significant[0]
        return chosen.effect, chosen, [chosen] + [f for f in fits if f is not chosen]
    return ("unexplained" if gap_is_real else "none"), None, fits
