"""What every stage runs on: the params schema (:mod:`~hnsdt.compose.params`) and the settings made from it
(:mod:`~hnsdt.compose.config`), the method registry (:mod:`~hnsdt.core.methods`), the stage functions the DVC
scripts call (:mod:`~hnsdt.core.stages`), the task runner (:mod:`~hnsdt.core.compute`), and the file, provenance
and reproducibility helpers. Every DVC stage depends on this folder as a whole."""
