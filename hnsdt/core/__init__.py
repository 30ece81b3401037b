"""The ground floor: what every layer above may use and nothing here imports from them — atomic file writes
(:mod:`.fileio`), same-seed-same-bytes settings (:mod:`.reproducible`), the method registry's facts
(:mod:`.methods`), provenance (:mod:`.provenance`) and the task runner (:mod:`.compute`)."""
