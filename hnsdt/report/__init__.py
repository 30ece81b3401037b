"""The report: ``report.md`` and its figures, one module per section it writes (:mod:`.write` puts them together).

Each figure is listed with the git revision, a digest of the params and the md5 of every dataset and model it
came from, as recorded in ``dvc.lock`` by the stages that produced them."""
