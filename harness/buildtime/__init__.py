"""Build-time code: what CMake runs while it packages the FMUs, the boundary it imports.

* :mod:`.references`: the FMUs' reference results (``python -m harness.buildtime.references``);
* :mod:`.documentation`: each FMU's ``documentation/index.html``;
* :mod:`.archive`: reproducible FMU archives;
* :mod:`.ssp_file`: the closed-loop SSP file (``python -m harness.buildtime.ssp_file``).

(The platforms the binaries are built for, :mod:`harness.platforms`, are ground: FMU access
reads them too.) These modules import the rest of the harness lazily or not at all (CMake runs them before
anything else is installed), and the harness's jobs reuse them (``identify export``).
"""
