"""Running many jobs, and nothing of the science: worker processes on this machine
(``workers``), Ray tasks on a cluster (``ray_backend``), the one door that chooses between them
(``backend``) and the stages' cache keys (``cache``). A job is a top-level function and its
picklable arguments; what it computes is its caller's business."""
