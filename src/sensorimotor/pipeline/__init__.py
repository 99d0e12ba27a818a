"""The paper's pipeline as reusable jobs: ``stages`` (make a database, train a stack of runs,
evaluate a run, analyse a representation), ``paper`` (the paper's stages over its three worlds,
cached: what ``reproduce`` runs first) and ``sweep`` (a search over training settings, each
trial an ordinary run folder)."""
