"""Plant models: plain numpy, batched over a leading dimension, no Gymnasium."""
