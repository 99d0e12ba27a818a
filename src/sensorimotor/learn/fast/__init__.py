"""Speed only: the stacked seeds' hand-written passes (checked against ``models.py`` before
training), CUDA graphs, and every private PyTorch function the project calls (``private``),
each with a public fallback. Removing this package's speed changes no number beyond float32
rounding."""
