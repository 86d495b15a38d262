"""The masters that run the loop, and the one place that says which is which.

A master runs a closed loop (controller and plant, a tracking scenario), the plant
alone (an open loop, a voltage sequence), or both. Each one is a module of this
package; :data:`MASTERS` says for each name what it runs, on which FMI versions and
which optional package it needs, and :func:`closed_loop`, :func:`open_loop` and
:func:`prepared_loop` hand out its functions. The jobs (``report``, ``sweep``,
``bench``, ``identify``) and the command line ask only this registry.

========================  ============  ==========  ===========  =============================
name                      closed loop   open loop   FMI          needs
========================  ============  ==========  ===========  =============================
``fmpy``                  yes           yes         2.0, 3.0     fmpy
``native``                yes           (fmpy's)    2.0          ``build/libpiezo_runner.so``
``auto``                  yes           (fmpy's)    2.0, 3.0     (native for long runs)
``core``                  yes           yes         none (cffi)  ``build/libpiezo_core.so``
``closed-loop-fmu``       yes           (fmpy's)    2.0, 3.0     fmpy
``ssp-player``            yes           no          2.0          fmpy (its SSP player)
``container``             yes           no          2.0          fmu-manipulation-toolbox
``wired``                 yes           no          2.0, 3.0     fmpy
========================  ============  ==========  ===========  =============================

The first five are the command line's ``--backend`` (or ``--master``) choices:
``closed-loop-fmu`` runs the loop inside one FMU, PiezoStageClosedLoop, with the same result;
``ssp-player`` and ``container`` run the loop in other tools' schedules
(docs/cosimulation.md) and ``wired`` the three FMUs wired by hand under any schedule, with
faults on the connections; they are called by their own functions.

Those functions, and what the jobs need beside them (the native master's kept instances, the
wired master's faults and schedules, the container's order), are this package's names
(:data:`__all__`): the jobs import them from here, never from a master's module
(``tests/test_harness_layout.py`` checks it).
"""

from __future__ import annotations

from dataclasses import dataclass
import functools

from ..binding.closed_loop import CLOSED_LOOP_MODEL
from ..fmu import CONTROLLER_MODEL, FMI_VERSIONS, PLANT_MODEL, REFERENCE_MODEL
from ..scenarios import get_scenario
from . import c_core, closed_loop_fmu, container, fmpy, native, ssp, wired
from .closed_loop_fmu import closed_loop_fmu_parameters, simulate_closed_loop_fmu_steps
from .container import CONTAINER_ORDER, ContainerTerminateWarning
from .fmpy import simulate_setup
from .instance import Instance
from .native import NativeLoop, live_bytes, missing_runner_message, native_available, native_loop
from .ssp import simulate_ssp_scenario
from .wired import SCHEDULES, Fault, WiredRun, schedule_name, simulate_wired

__all__ = ["Master", "MASTERS", "BACKENDS", "OPEN_LOOP_BACKENDS", "SWEEP_BACKENDS",
           "LONG_RUN_SAMPLES", "get", "closed_loop", "open_loop", "prepared_loop", "prepared_batch",
           "simulators", "simulate_closed_loop_auto", "check_sweep_backend",
           # closed-loop-fmu: a run of communication steps of any sizes, its parameters
           "simulate_closed_loop_fmu_steps", "closed_loop_fmu_parameters",
           # container: its schedules, the Warning it gives at terminate
           "CONTAINER_ORDER", "ContainerTerminateWarning",
           # fmpy: one prepared loop; ssp-player: a scenario through the SSP
           "simulate_setup", "simulate_ssp_scenario",
           # one FMU instance as the masters drive it
           "Instance",
           # native: the kept instances, whether the runner is built, the C heap in use
           "NativeLoop", "native_loop", "native_available", "missing_runner_message", "live_bytes",
           "NATIVE_PLANT", "NATIVE_CONTROLLER",
           # wired: the loop wired by hand, under a schedule, with faults
           "simulate_wired", "Fault", "WiredRun", "SCHEDULES", "schedule_name"]

#: the native master's instance indices (:meth:`NativeLoop.log`)
NATIVE_PLANT, NATIVE_CONTROLLER = native.PLANT, native.CONTROLLER


@dataclass(frozen=True)
class Master:
    """What one master runs.

    Attributes
    ----------
    name : str
    summary : str
        One line: what runs the loop.
    closed_loop, open_loop : bool
        It runs a closed loop / the plant alone itself (a master without an open loop of
        its own leaves the plant alone to fmpy's).
    fmi_versions : tuple of int
        The FMU editions it runs; empty for the C core (no FMI).
    needs : str
        What must be installed or built for it.
    backend : bool
        One of the command line's ``--backend`` choices.
    fmi_note : str
        Why it runs only the FMI versions it runs (for messages), or "".
    fmus : tuple of str
        The FMUs it runs (a run's provenance names them), the plant's for the open loop too.
    """

    name: str
    summary: str
    # what it runs
    closed_loop: bool
    open_loop: bool
    fmi_versions: tuple
    # what it takes, and whether the command line offers it
    needs: str
    backend: bool = True
    fmi_note: str = ""
    fmus: tuple = (PLANT_MODEL, CONTROLLER_MODEL)


MASTERS = {m.name: m for m in (
    Master("auto", "the native master for runs of LONG_RUN_SAMPLES and more, fmpy otherwise",
           True, False, (2, 3), "the native runner for long runs (else fmpy)"),
    Master("fmpy", "the FMUs through fmpy, values exchanged at communication points",
           True, True, (2, 3), "fmpy"),
    Master("native", "the same FMUs and loop in the C master of fmu_src/runner",
           True, False, (2,), "build/libpiezo_runner.so",
           fmi_note="the native master calls the fmi2 functions"),
    Master("core", "the C core through cffi, no FMI", True, True, (), "build/libpiezo_core.so",
           fmi_note="the core backend runs no FMU", fmus=()),
    Master("closed-loop-fmu", "the loop inside one FMU, PiezoStageClosedLoop, through fmpy",
           True, False, (2, 3), "fmpy", fmus=(CLOSED_LOOP_MODEL, PLANT_MODEL)),
    Master("ssp-player", "fmpy's SSP player on the closed-loop SSP (a Jacobi schedule)",
           True, False, (2,), "fmpy", backend=False,
           fmus=(PLANT_MODEL, CONTROLLER_MODEL, REFERENCE_MODEL)),
    Master("container", "an FMU container of fmu-manipulation-toolbox (parallel or sequential)",
           True, False, (2,), "fmu-manipulation-toolbox", backend=False),
    Master("wired", "the three FMUs wired by hand under any schedule (exchange, player, "
           "Gauss-Seidel in any order), faults on the connections", True, False, (2, 3), "fmpy",
           backend=False, fmus=(PLANT_MODEL, CONTROLLER_MODEL, REFERENCE_MODEL)),
)}

#: ``--backend`` of ``all`` and ``run``
BACKENDS = tuple(n for n, m in MASTERS.items() if m.backend)
#: ``--backend`` where only the plant runs (``identify``)
OPEN_LOOP_BACKENDS = tuple(n for n in BACKENDS if MASTERS[n].open_loop)
#: ``--backend`` of ``sweep``: the masters that keep their instances from run to run
#: (:func:`prepared_loop`), the default first
SWEEP_BACKENDS = ("native", "fmpy")

#: Runs of at least this many samples (10 s at 2 kHz) use the native master under ``auto``.
LONG_RUN_SAMPLES = 20000


def get(name):
    """The :class:`Master` of a name (ValueError naming the valid ones)."""
    try:
        return MASTERS[name]
    except KeyError:
        raise ValueError(f"master must be one of {', '.join(MASTERS)}, got {name!r}") from None


def simulate_closed_loop_auto(scenario, *, registry=None, duration=None, fmi_version=2, **kwargs):
    """:func:`harness.masters.native.simulate_closed_loop_native` for runs of at least
    ``LONG_RUN_SAMPLES`` samples when the runner is built, else
    :func:`harness.masters.fmpy.simulate_closed_loop` (same result either way); the FMI 3.0
    editions (``fmi_version=3``) always run with fmpy."""
    sc = get_scenario(scenario, registry)
    n = sc.n_samples if duration is None else int(round(float(duration) / float(sc.step_size)))
    if fmi_version == 2 and n >= LONG_RUN_SAMPLES and native.native_available():
        return native.simulate_closed_loop_native(sc, registry=registry, duration=duration, **kwargs)
    return fmpy.simulate_closed_loop(sc, registry=registry, duration=duration,
                                     fmi_version=fmi_version, **kwargs)


def _check(name, fmi_version):
    """Refuse an unknown master, or an FMI version it does not run (ValueError)."""
    if fmi_version not in FMI_VERSIONS:
        raise ValueError(f"fmi_version must be 2 or 3, got {fmi_version!r}")
    if name not in MASTERS:
        raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {name!r}")
    if fmi_version not in MASTERS[name].fmi_versions and fmi_version != 2:
        if name == "core":
            raise ValueError("the core backend runs the C core without FMI: an FMI version does "
                             "not apply to it")
        if name == "native":
            raise ValueError(native.FMI3_REFUSAL)
        raise ValueError(f"the {name} master runs the FMI 2.0 editions only")


def closed_loop(name, fmi_version=2):
    """The closed-loop function of a master.

    For the ``--backend`` choices: ``f(scenario, *, adaptation, preview, master, fmu_dir,
    progress, ...)`` (see :func:`harness.masters.fmpy.simulate_closed_loop`;
    ``closed-loop-fmu``: :func:`harness.masters.closed_loop_fmu.simulate_closed_loop_fmu`); ``ssp-player``:
    :func:`harness.masters.ssp.simulate_ssp_scenario`; ``container``:
    :func:`harness.masters.container.simulate_closed_loop_container`; ``wired``:
    :func:`harness.masters.wired.simulate_wired`.

    Raises
    ------
    ValueError
        An unknown master, or an FMI version it does not run (the core runs no FMU; the
        native master and other tools' only the FMI 2.0 editions).
    """
    _check(name, fmi_version)
    if name == "core":
        return c_core.simulate_closed_loop_core
    if name == "ssp-player":
        return ssp.simulate_ssp_scenario
    if name == "container":
        return container.simulate_closed_loop_container
    if name == "wired":
        return functools.partial(wired.simulate_wired, fmi_version=fmi_version)
    if name == "closed-loop-fmu":
        return functools.partial(closed_loop_fmu.simulate_closed_loop_fmu, fmi_version=fmi_version)
    if fmi_version != 2:                 # fmpy (also for auto): the FMI 3.0 editions
        return functools.partial(fmpy.simulate_closed_loop, fmi_version=fmi_version)
    if name == "native":
        return native.simulate_closed_loop_native
    if name == "auto":
        return simulate_closed_loop_auto
    return fmpy.simulate_closed_loop


def open_loop(name, fmi_version=2):
    """The plant-alone function of a master: ``f(plant_params, v, *, step_size, fmu_dir,
    progress)`` (see :func:`harness.masters.fmpy.simulate_open_loop`); a master without an
    open loop of its own gives fmpy's. Raises ValueError as :func:`closed_loop`."""
    _check(name, fmi_version)
    if name == "core":
        return c_core.simulate_open_loop_core
    if fmi_version != 2:
        return functools.partial(fmpy.simulate_open_loop, fmi_version=fmi_version)
    return fmpy.simulate_open_loop


def simulators(backend, fmi_version=2):
    """``(closed_loop(backend, fmi_version), open_loop(backend, fmi_version))``."""
    return closed_loop(backend, fmi_version), open_loop(backend, fmi_version)


def check_sweep_backend(backend):
    """Refuse a master that cannot run a sweep's prepared loops here.

    Raises
    ------
    ValueError
        ``backend`` is not one of :data:`SWEEP_BACKENDS`.
    FileNotFoundError
        The native runner library is not built (the message says how to build it).
    """
    if backend not in SWEEP_BACKENDS:
        raise ValueError(f"backend must be 'native' or 'fmpy', got {backend!r}")
    if backend == "native" and not native.native_available():
        raise FileNotFoundError(native.missing_runner_message())


def prepared_loop(backend, fmu_dir=None):
    """A function ``run(setup)`` that runs a prepared closed loop
    (:class:`harness.loop.ClosedLoopSetup`) on this thread's instances of the FMUs in
    ``fmu_dir``, kept from run to run: the runs of a sweep. Raises as
    :func:`check_sweep_backend`.
    """
    check_sweep_backend(backend)
    if backend == "native":
        return native.native_loop(fmu_dir).run
    return functools.partial(fmpy.simulate_setup, fmu_dir=fmu_dir)


def prepared_batch(backend, fmu_dir=None):
    """A function ``run_batch(setup, per_run, window)`` that runs many parameter sets of one
    prepared closed loop in one call on this thread's instances
    (:meth:`harness.masters.native.NativeLoop.run_batch`), or None when the master has none
    (fmpy: its runs go one by one through :func:`prepared_loop`). Raises as
    :func:`check_sweep_backend`.
    """
    check_sweep_backend(backend)
    return native.native_loop(fmu_dir).run_batch if backend == "native" else None
