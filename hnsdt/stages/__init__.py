"""The pipeline's stages as functions, one module per DVC stage (so a stage depends on its own module, and an edit
to one reruns that stage alone): each takes the validated params (:func:`hnsdt.compose.config.load_params`) and
explicit paths, does its work on the executor of ``compute`` and writes its outputs, each complete or absent.

The DVC stage scripts in ``pipeline/`` call them through :func:`hnsdt.stages.common.run`, which gives them the
command line's error contract; the ``hnsdt`` subcommands of the same names call them too. This file imports
nothing, so that importing one stage loads no other.
"""
