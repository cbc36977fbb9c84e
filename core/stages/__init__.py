# SPDX-License-Identifier: LGPL-2.1-or-later
"""The pipeline's stages, one module each: a function from typed results (``core.types``) to
the stage's own typed result, which carries its report section.

Every stage is called as ``run(*inputs, params, progress)`` by ``core.pipeline.run_stages``
(the inputs are the results the stage declares in ``core.pipeline.STAGES``); ``progress``
is the stage's share of the run's bar (``core.progress.SubProgress``), which it reports to
and which raises ``Cancelled`` when the user stops. A stage imports its algorithms inside
its function, so importing the pipeline (the command line, FreeCAD's start-up) stays light.
"""
