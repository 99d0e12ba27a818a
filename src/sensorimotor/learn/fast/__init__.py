"""Speed only: the stacked seeds' hand-written passes and the check that lets them train
(``check``: they compute what ``models.py`` computes), CUDA graphs, the optimiser's fused Adam
(``adam``), CPU process settings (``cpu``), and every private PyTorch function the project calls
(``private``), each with a public fallback. Removing this package's speed changes no number
beyond float32 rounding.

It imports, of ``learn``, only the model definition (``models``) and the batching
(``batches``); the rest of the package reaches it through ``learn.engine`` alone."""
