"""The report: ``document`` writes ``report.md`` and a self-contained ``report.html`` from what
the paper's stages found (Table I, figures, the paper's claims with their verdicts) and the
sections the experiments hand it, built of ``blocks``. It never imports an experiment."""
