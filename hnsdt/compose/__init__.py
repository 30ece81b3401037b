"""The composition layer: the params schema (:mod:`.params`), the settings made from it (:mod:`.config`), the
experiments' layout splits (:mod:`.generalisation`) and the training plans (:mod:`.training`); the stages
(:mod:`hnsdt.stages`) and the report (:mod:`hnsdt.report`) run on them."""
