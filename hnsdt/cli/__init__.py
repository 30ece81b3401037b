"""The ``hnsdt`` command (:func:`main`): thin parsing (:mod:`.parser`) over the commands (:mod:`.commands`), which
run the pipeline's stages (:mod:`hnsdt.stages`) and the tools around them."""

from hnsdt.cli.entry import main

__all__ = ["main"]
