"""The paper's figures of the simulator (``figures``), the whole reproduction (``reproduce``),
its report (``document``) and the worker processes that run its jobs (``workers``)."""
