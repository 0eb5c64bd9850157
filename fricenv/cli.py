"""The ``fricenv`` console script: one verb per module, one error path, progress bars, clean interrupts.

Each verb lives in its own module exposing ``add_arguments(parser)`` and ``run(args) -> int``; this file only maps
verb names to modules, so adding a verb never touches another verb's code. Modules are imported when the parser is
built, so they keep heavy imports (torch, casadi, SB3) inside ``run``.

:func:`main` is the one place where errors meet the user:

* a user's mistake (a :class:`fricenv.errors.FricenvError`, a known domain error, a bad option, a missing or
  unwritable file, a verb that exits with a message) prints one line ``fricenv <full subcommand>: error: ...``
  (``fricenv gap diagnose: error: ...``) on stderr and returns 2;
* 1 means "finished, with failed rows": a fleet command (``gap diagnose DIR``) that ran every row and wrote its
  table, where some rows failed (they are named in the table);
* SIGINT (Ctrl-C) and SIGTERM stop the work and its worker processes, print one line and return 130 / 143;
* a closed stdout (``fricenv ... | head``) ends the command quietly with 141;
* anything else is a bug and keeps its traceback.

Input files and output paths named by the options in :data:`PATH_OPTIONS` are checked before the verb runs, so a
bad ``--out`` or ``--params`` is reported before any long work.
"""

from __future__ import annotations

import argparse
import contextlib
import glob
import importlib
import multiprocessing
import os
import signal
import sys
import threading
import time

from fricenv import progress
from fricenv.errors import InvalidInputError, is_user_error, one_line
from fricenv.utils import check_input_file, check_output_dir, check_output_file

# (verb, sub-verb or None) -> module. Order is the order shown by --help.
VERBS: dict[tuple[str, str | None], str] = {
    ("demo", None): "fricenv.commands.demo",
    ("bench", None): "fricenv.commands.bench",
    ("paper", "mhe"): "fricenv.commands.paper_mhe",
    ("paper", "ekf-rls"): "fricenv.commands.paper_ekf_rls",
    ("paper", "fms"): "fricenv.commands.paper_fms",
    ("paper", "robustness"): "fricenv.commands.paper_robustness",
    ("excitation", None): "agents.commands.excitation",
    ("train", None): "agents.commands.train",
    ("tune", None): "agents.commands.tune",
    ("evaluate", None): "agents.commands.evaluate",
    ("compare", None): "agents.commands.compare",
    ("gap", "simulate"): "fricenv.commands.gap_simulate",
    ("gap", "diagnose"): "fricenv.commands.gap_diagnose",
    ("gap", "convert"): "fricenv.commands.gap_convert",
    ("gap", "policy"): "agents.commands.gap_policy",
    ("gap", "validate"): "fricenv.commands.gap_validate",
}

# Option dest -> what it names, checked before the verb runs. A verb module overrides an entry with a module-level
# ``PATH_OPTIONS`` dict (e.g. gap simulate's --out is a file, not a directory).
PATH_CHECKS = {"input file": check_input_file, "output file": check_output_file, "output dir": check_output_dir}
PATH_OPTIONS: dict[str, str] = {
    "log": "input file",
    "params": "input file",
    "report": "input file",
    "json": "output file",
    "log_out": "output file",
    "out": "output dir",
    "report_out": "output dir",
}

EXIT_USER_ERROR = 2
EXIT_SIGNAL_BASE = 128  # exit code 128 + signal number: 130 for SIGINT, 143 for SIGTERM


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors take the one error path (one line, exit code 2)."""

    def error(self, message: str):
        raise InvalidInputError(f"{message} (see {self.prog} --help)")


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived; raised in the main thread by the handler :func:`main` installs."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _load(module_name: str):
    """The verb module, or None if that verb is not part of this installation yet."""
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name == module_name:
            return None
        raise


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("fricenv")
    except PackageNotFoundError:
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser, one sub-parser per available verb."""
    parser = _Parser(prog="fricenv", description="Tire-road friction and force-sensor calibration workbench.")
    parser.add_argument("--version", action="version", version=f"fricenv {_version()}")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    verbs = parser.add_subparsers(dest="verb", metavar="VERB", required=True)
    groups: dict[str, argparse._SubParsersAction] = {}
    for (verb, sub), module_name in VERBS.items():
        module = _load(module_name)
        if module is None:
            continue
        doc = (module.__doc__ or "").strip().splitlines()
        help_text = doc[0] if doc else None
        if sub is None:
            p = verbs.add_parser(verb, help=help_text, description=module.__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
        else:
            if verb not in groups:
                group_parser = verbs.add_parser(verb, help=f"{verb} sub-commands")
                groups[verb] = group_parser.add_subparsers(dest="sub", metavar="SUB", required=True)
            p = groups[verb].add_parser(sub, help=help_text, description=module.__doc__,
                                        formatter_class=argparse.RawDescriptionHelpFormatter)
        module.add_arguments(p)
        p.set_defaults(_run=module.run, _prog=p.prog, _paths={**PATH_OPTIONS, **getattr(module, "PATH_OPTIONS", {})})
    return parser


def check_paths(args: argparse.Namespace) -> None:
    """Check every input file and output path the options name (see :data:`PATH_OPTIONS`); nothing is created.

    :raises FricenvError: one line naming the option, the path and what is wrong.
    """
    for dest, kind in args._paths.items():
        value = getattr(args, dest, None)
        if value is not None:
            what = dest if kind == "input file" and dest == "log" else "--" + dest.replace("_", "-")
            PATH_CHECKS[kind](value, what)


class TqdmSink:
    """The CLI's progress sink: one tqdm bar per open task on ``stream`` (stderr), nested tasks below their parent.

    Events from another process (a forked worker inherits the sink) are ignored, so only the front end draws.
    """

    def __init__(self, stream=None, mininterval: float = 0.1):
        """:param stream: where the bars go (default stderr). :param mininterval: least seconds between redraws."""
        self._stream = stream if stream is not None else sys.stderr
        self._mininterval = mininterval
        self._bars: list = []
        self._pid = os.getpid()

    def start(self, label: str, total: int | None) -> None:
        from tqdm.auto import tqdm

        if os.getpid() == self._pid:
            self._bars.append(tqdm(total=total, desc=label, file=self._stream, leave=False,
                                   position=len(self._bars), dynamic_ncols=True,
                                   mininterval=self._mininterval))

    def advance(self, n: int) -> None:
        if os.getpid() == self._pid and self._bars:
            self._bars[-1].update(n)

    def finish(self) -> None:
        if os.getpid() == self._pid and self._bars:
            self._bars.pop().close()


def progress_sink(quiet: bool, stdout_is_terminal: bool, prog: str = "fricenv"
                  ) -> TqdmSink | progress.LineSink | None:
    """The sink :func:`main` installs: bars on stderr when stdout is a terminal, stage and progress lines on stderr
    (:class:`fricenv.progress.LineSink`, prefixed with ``prog``) when it is not, None with ``--quiet``."""
    if quiet:
        return None
    return TqdmSink() if stdout_is_terminal else progress.LineSink(prog)


def _multiprocessing_helpers() -> set[int]:
    """The resource tracker and fork server of multiprocessing: they end with this process and are reused by later
    pools, so they are not stopped."""
    from multiprocessing import forkserver, resource_tracker

    pids = {getattr(resource_tracker._resource_tracker, "_pid", None),
            getattr(forkserver._forkserver, "_forkserver_pid", None)}
    return {pid for pid in pids if pid is not None}


def _child_pids() -> set[int]:
    """Direct child processes of this one, from /proc (Linux; empty elsewhere), multiprocessing's helpers left out."""
    pids: set[int] = set()
    for path in glob.glob(f"/proc/{os.getpid()}/task/*/children"):
        try:
            with open(path) as fh:
                pids.update(int(pid) for pid in fh.read().split())
        except OSError:
            continue
    return pids - _multiprocessing_helpers()


def _reap(pid: int, timeout: float) -> bool:
    """Wait up to ``timeout`` seconds for child ``pid`` to exit; True once it has (or is not our child)."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            done, _ = os.waitpid(pid, os.WNOHANG)
        except ChildProcessError:
            return True
        if done or time.monotonic() > deadline:
            return bool(done)
        time.sleep(0.02)


def stop_workers(timeout: float = 5.0) -> None:
    """Terminate this process's worker processes and reap them: multiprocessing children (process pools, subprocess
    vector envs) and any other direct child, e.g. one forked just as an interrupt arrived and so never recorded by
    the pool that started it (SIGTERM, then SIGKILL after ``timeout`` seconds)."""
    children = multiprocessing.active_children()
    others = _child_pids() - {child.pid for child in children}
    for child in children:
        child.terminate()
    for pid in others:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGTERM)
    for child in children:
        child.join(timeout=timeout)
        if child.is_alive():
            child.kill()
            child.join()
    for pid in others:
        if not _reap(pid, timeout):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
            _reap(pid, timeout)


class _Signals:
    """SIGINT and SIGTERM while a command runs: stop the workers and raise :class:`Interrupted` in the main thread.

    The raise can land where Python swallows it (e.g. inside an at-fork callback while a process pool starts a
    worker), so the signal is also recorded in :attr:`signum` and delivered again every ``REDELIVER_S`` seconds until
    :meth:`settle`. A forked worker that inherited the handler exits at once, quietly. Previous handlers are restored
    on exit.
    """

    REDELIVER_S = 1.0

    def __init__(self):
        self.signum: int | None = None
        self._lock = threading.Lock()
        self._active = False
        self._timer: threading.Timer | None = None
        self._previous: dict = {}
        self._unraisablehook = sys.unraisablehook
        self._excepthook = threading.excepthook
        self._pid = os.getpid()

    def __enter__(self) -> _Signals:  # noqa: PYI034  (typing.Self needs Python 3.11)
        if threading.current_thread() is threading.main_thread():
            self._active = True
            self._previous = {sig: signal.signal(sig, self._handle) for sig in (signal.SIGINT, signal.SIGTERM)}
            self._unraisablehook, sys.unraisablehook = sys.unraisablehook, self._unraisable
            self._excepthook, threading.excepthook = threading.excepthook, self._thread_error
        return self

    def _unraisable(self, unraisable) -> None:
        """An :class:`Interrupted` Python had to swallow is not printed: it is recorded and delivered again."""
        if not isinstance(unraisable.exc_value, Interrupted):
            self._unraisablehook(unraisable)

    def _thread_error(self, args) -> None:
        """After an interrupt, a helper thread that fails as its workers vanish (a process pool's manager thread)
        is a consequence of the interrupt, not news: not printed."""
        if self.signum is None:
            self._excepthook(args)

    def _handle(self, signum: int, frame) -> None:
        if os.getpid() != self._pid:
            os._exit(EXIT_SIGNAL_BASE + signum)
        if not self._active:  # already settled: main is reporting the interrupt
            return
        self.signum = signum
        stop_workers()
        self._timer = threading.Timer(self.REDELIVER_S, self._redeliver, args=(signum,))
        self._timer.daemon = True
        self._timer.start()
        raise Interrupted(signum)

    def _redeliver(self, signum: int) -> None:
        with self._lock:
            if self._active:
                os.kill(self._pid, signum)

    def settle(self) -> None:
        """The command has ended: no more raising, no redelivery."""
        with self._lock:
            self._active = False
        if self._timer is not None:
            self._timer.cancel()

    def __exit__(self, *exc_info) -> None:
        self.settle()
        for sig, old in self._previous.items():
            signal.signal(sig, old)
        if self._previous:
            sys.unraisablehook = self._unraisablehook
            threading.excepthook = self._excepthook


def _silence_stdout() -> None:
    """Point stdout at /dev/null, so the interpreter's final flush into a closed pipe raises nothing."""
    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except (OSError, ValueError):  # a stdout without a file descriptor (captured in tests)
        pass


def _interrupted(prog: str, signum: int) -> int:
    stop_workers()
    print(f"{prog}: interrupted by {signal.Signals(signum).name}; stopped", file=sys.stderr)
    return EXIT_SIGNAL_BASE + signum


def _strip_prog(message: str, prog: str) -> str:
    """A message without a leading ``fricenv VERB:`` or ``error:`` of its own (the one format adds them)."""
    for head in (f"{prog}: error:", f"{prog}:", "error:"):
        if message.startswith(head):
            return message[len(head):].strip()
    return message


def _fail(prog: str, message: str) -> None:
    print(f"{prog}: error: {message}", file=sys.stderr)


def _run_verb(args: argparse.Namespace) -> int:
    """Check the paths, then run the verb with the progress sink installed."""
    check_paths(args)
    sink = progress_sink(args.quiet, sys.stdout.isatty(), args._prog)
    args.show_progress = isinstance(sink, TqdmSink)  # a verb's own bars (SB3's) only on a terminal
    with progress.use_sink(sink):
        return int(args._run(args) or 0)


def _dispatch(argv: list[str] | None, context: dict, signals: _Signals) -> int:
    """Parse and run; a user's error becomes one line and exit code 2 (see :func:`main`)."""
    try:
        parser = build_parser()
        try:
            args = parser.parse_args(argv)
        except InvalidInputError as exc:
            _fail(context["prog"], one_line(exc))
            return EXIT_USER_ERROR
        context["prog"] = args._prog
        return _run_verb(args)
    except SystemExit as exc:  # --help, --version, or a verb that exits with a message
        if isinstance(exc.code, str):
            _fail(context["prog"], _strip_prog(" ".join(exc.code.split()), context["prog"]))
            return EXIT_USER_ERROR
        return 0 if exc.code is None else int(exc.code)
    except BrokenPipeError:  # stdout closed early (e.g. piped into head): stop quietly, as POSIX tools do
        _silence_stdout()
        return EXIT_SIGNAL_BASE + signal.SIGPIPE
    except Exception as exc:
        if signals.signum is not None or not is_user_error(exc):
            raise
        _fail(context["prog"], one_line(exc))
        return EXIT_USER_ERROR


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``fricenv`` console script; returns the exit code (see the module docstring)."""
    context = {"prog": "fricenv"}
    with _Signals() as signals:
        try:
            code = _dispatch(argv, context, signals)
        except BaseException:
            signals.settle()
            if signals.signum is None:
                raise
        signals.settle()
        if signals.signum is not None:  # also when the interrupt was swallowed or the work ended anyway
            return _interrupted(context["prog"], signals.signum)
        return code


if __name__ == "__main__":
    sys.exit(main())
