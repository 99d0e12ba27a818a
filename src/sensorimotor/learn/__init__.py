"""Learning by sensorimotor prediction: the four encoders (``models``), how a model is trained
(``config``: its settings; ``train``: one loop for one seed or many, driving an ``engine``), the
run folders it writes (``runs``) and their evaluation (``evaluate``). Code that exists only for
speed is in ``fast``, which the rest reaches through ``engine`` alone."""
