"""The closed loop under every master that installs here, on the mismatch case of docs/model.md,
with every FMU at its defaults (issue 21: the loop finds its own timing).

Masters (their real schedules read in their sources, see harness/masters/ssp.py and container.py):
  * ours (harness.masters.fmpy): Gauss-Seidel in ModelStructure order with either doStep order,
    and a textbook Jacobi master;
  * fmu-manipulation-toolbox's container FMU, parallel mode (set all, step all, get all);
  * fmpy's SSP player (Jacobi, connectors start at 0 instead of the initial outputs);
  * the same container in sequential mode, each of the 6 orders of its FMU list (each FMU
    gets the post-step outputs of the ones before it: true Gauss-Seidel, one sample less
    loop delay);
each also with a plant whose input is one sample late (tf.delay = 1).

Independent references: the loop delay and the stamps each schedule makes, worked out from
the schedule (docs/cosimulation.md, section 2): d = 2 where values are exchanged at
communication points, 1 in true Gauss-Seidel, plus tf.delay; the measurement is one sample
ahead of the controller's time when the plant is stepped before it, the stamped preview
4 + (1 if ReferenceSignal is stepped before the controller) samples ahead of the controller's
time. For the exchange masters: our Gauss-Seidel run; for fmpy's player a Jacobi loop written
here on the core binding that starts its exchanged values at 0 as the player does; each equal
bit for bit at every sample. Every run: e_rms <= 3 nm over [1, 3) s (the issue's bound).
"""
import itertools

import numpy as np
import pytest

from harness.binding import core
from harness.loop import REFERENCE_LEAD, REFERENCE_PREVIEW
from harness.masters import container
from harness.masters.fmpy import simulate_closed_loop
from harness.masters.ssp import simulate_ssp_scenario
from harness.loop.metrics import compute_metrics
from harness.scenarios import MISMATCH_SCENARIOS, get_scenario

FIELDS = ("y_d", "y", "y_meas", "v")
E_RMS_MAX = 3e-3     # um
D1 = {"mv.delay": 0, "mv.feedthrough": True}
R, C, P = container.CONTAINER_ORDER
ORDERS = list(itertools.permutations((R, C, P)))


def e_rms(name, run):
    sc = get_scenario(name)
    return compute_metrics(run["time"], run["y_d"], run["y"], sc.metric_window, sc.step_size).e_rms


def differ(a, b):
    """The FIELDS in which two runs differ (any bit of any sample; [] when they are equal)."""
    assert len(a) == len(b), (len(a), len(b))
    return [f for f in FIELDS if not np.array_equal(np.asarray(a[f]).view(np.uint64), np.asarray(b[f]).view(np.uint64))]


def detected(run):
    """The controller's timing outputs at the end of an importer's run."""
    return {f: run[f][-1] for f in ("loop_delay", "preview_lead", "meas_offset")}


def zero_start_jacobi(name, tf_delay=0):
    """fmpy's SSP player, rewritten on the core binding: per step, every component steps with
    the current connector values, then outputs are copied to inputs; the connectors start at
    0. The reference's outputs after its step from t_k: y_ref = y_d(t_(k+1) + 2 h), the stamped
    preview y_d(t_(k+1) + 4 h) at t_(k+1) + 4 h; the plant's t_meas = t_(k+1). The FMU counts a
    time stamp once it advanced by h since the last sample: t_meas from the player's first real
    value on (0 -> h), t_preview from the second (0 -> 5 h is no advance of h), so the preview
    lead is 4 from sample 2 on. Rows are the values after the step from t_k, i.e. at t_(k+1),
    as the player records them."""
    sc = get_scenario(name)
    h, n = sc.step_size, sc.n_samples
    plant = core.Plant({**sc.plant, "h": h, "tf.delay": tf_delay})
    ctrl = core.Controller({**sc.controller, "h": h})
    y_d = sc.signal.evaluate(np.arange(n + 6) * h)
    c_y_ref = c_y_preview = c_y_meas = c_v = 0.0
    rows = np.zeros(n, dtype=[(f, "f8") for f in ("time",) + FIELDS])
    for k in range(n):
        published = ctrl.step_input(c_y_ref, c_y_meas, c_y_preview, REFERENCE_PREVIEW if k >= 2 else 0)
        out = plant.step(c_v)
        c_y_ref, c_y_preview = y_d[k + 1 + REFERENCE_LEAD], y_d[k + 1 + REFERENCE_PREVIEW]
        c_y_meas, c_v = out.y_meas, published.v
        rows[k] = ((k + 1) * h, y_d[k + 1], out.y, out.y_meas, published.v)
    return rows


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return tmp_path_factory.mktemp("masters")


@pytest.mark.parametrize("tf_delay", [0, 1])
@pytest.mark.parametrize("name", MISMATCH_SCENARIOS)
def test_exchange_at_communication_points_gives_the_same_samples(name, tf_delay, workdir):
    """Our Gauss-Seidel in both doStep orders, our Jacobi and the parallel container run the
    same loop: every sample bit for bit that of the Gauss-Seidel run. The controller detects
    d = 2 + tf.delay there (and in our runs), the preview 4 samples ahead of a measurement of
    its own time."""
    plant = {"tf.delay": tf_delay}
    timing = {}
    gs = simulate_closed_loop(name, plant_params=plant, timing=timing)
    assert (timing["loop_delay"], timing["preview_lead"], timing["meas_offset"]) == (2 + tf_delay, 4, 0)
    runs = {"gauss-seidel controller-first": simulate_closed_loop(name, step_order="controller-first",
                                                                  plant_params=plant),
            "jacobi": simulate_closed_loop(name, master="jacobi", plant_params=plant)}
    sc = get_scenario(name)
    path = container.build_closed_loop_container(name, workdir / f"{name}_{tf_delay}_par.fmu",
                                                 plant_params=plant)
    runs["container parallel"] = container.simulate_container(path, sc.duration, sc.step_size)
    assert detected(runs["container parallel"]) == {"loop_delay": 2 + tf_delay, "preview_lead": 4,
                                                    "meas_offset": 0}
    for master, run in runs.items():
        assert differ(run, gs) == [], master
    assert e_rms(name, gs) <= E_RMS_MAX


def test_a_container_refusing_to_terminate_keeps_the_run(workdir):
    """The controller's voltage limits at 70 % of the peak the 5 Hz run needs: it clips, so
    its terminate returns a Warning with the count, which fmu-manipulation-toolbox's
    container turns into an Error of its own terminate (measured: "failed to terminate").
    simulate_container keeps the run: every sample bit for bit that of our Gauss-Seidel run with
    the same limits (reference), and a ContainerTerminateWarning quoting the controller's
    summary."""
    name, limits = "mismatch_5hz", {"sat.v_min": -12.6, "sat.v_max": 12.6}
    sc = get_scenario(name)
    path = container.build_closed_loop_container(name, workdir / "clipping.fmu", controller_params=limits)
    with pytest.warns(container.ContainerTerminateWarning, match="v was clipped in [1-9]"):
        run = container.simulate_container(path, sc.duration, sc.step_size)
    ref = simulate_closed_loop(name, controller_params=limits)
    assert differ(run, ref) == []
    assert np.any(np.abs(ref["v"]) == 12.6)


@pytest.mark.parametrize("tf_delay", [0, 1])
@pytest.mark.parametrize("name", MISMATCH_SCENARIOS)
def test_fmpy_ssp_player_runs_our_loop_from_its_zero_start(name, tf_delay):
    """fmpy's SSP player equals the zero-start Jacobi loop bit for bit at every sample and
    stays within the bound; the controller detects d = 2 + tf.delay. Its start differs from
    our loop (its first control sees y_ref = 0 instead of y_d(2 h)): measured, the samples
    differ by more than 1 nm."""
    ssp = simulate_ssp_scenario(name, plant_params={"tf.delay": tf_delay})
    ref = zero_start_jacobi(name, tf_delay)
    assert differ(ssp, ref) == []
    assert e_rms(name, ssp) <= E_RMS_MAX
    assert detected(ssp) == {"loop_delay": 2 + tf_delay, "preview_lead": 4, "meas_offset": 0}
    if tf_delay == 0:
        ours = simulate_closed_loop(name)
        assert np.max(np.abs(ssp["y"][:-1] - ours["y"][1:])) > 1e-3


@pytest.mark.parametrize("tf_delay", [0, 1])
@pytest.mark.parametrize("order", ORDERS, ids=["".join(f[0] for f in o) for o in ORDERS])
@pytest.mark.parametrize("name", MISMATCH_SCENARIOS)
def test_sequential_container_in_every_order_tracks_with_the_defaults(name, order, tf_delay, workdir):
    """True Gauss-Seidel (the sequential container) in each of the 6 orders of its FMU list,
    every FMU at its defaults: the controller detects d = 1 + tf.delay, the measurement one
    sample ahead when the plant is stepped before it, the stamped preview 4 + (1 if the
    reference is stepped before it) samples ahead of its time, and the loop tracks within
    3 nm; no run is stopped by the monitor (a stopped run raises). The figures are in the
    table of docs/cosimulation.md (python -m harness timing)."""
    sc = get_scenario(name)
    path = container.build_closed_loop_container(name, workdir / "seq.fmu", sequential=True, order=order,
                                                 plant_params={"tf.delay": tf_delay})
    seq = container.simulate_container(path, sc.duration, sc.step_size, sequential=True)
    o = 1 if order.index(P) < order.index(C) else 0
    r = 1 if order.index(R) < order.index(C) else 0
    assert detected(seq) == {"loop_delay": 1 + tf_delay, "preview_lead": REFERENCE_PREVIEW + r - o,
                             "meas_offset": o}
    assert e_rms(name, seq) <= E_RMS_MAX


@pytest.mark.parametrize("name", ["mismatch_5hz", "mismatch_1_5_10hz"])
def test_sequential_container_configured_by_hand_still_runs_the_d1_loop(name, workdir):
    """The explicit configuration of today keeps working: the sequential container in the
    links' order reference -> controller -> plant with mv.delay = 0 and lead = 0 (the
    controller gets the reference's post-step output) equals our Gauss-Seidel run of the
    direct-feedthrough loop (mv.feedthrough, mv.delay = 0) bit for bit at every sample."""
    sc = get_scenario(name)
    path = container.build_closed_loop_container(
        name, workdir / f"{name}_seq_set.fmu", sequential=True,
        controller_params={"mv.delay": 0}, reference_params={"lead": 0})
    seq = container.simulate_container(path, sc.duration, sc.step_size, sequential=True)
    d1 = simulate_closed_loop(name, controller_params=D1)
    assert differ(seq, d1) == []
    assert e_rms(name, seq) <= E_RMS_MAX


def test_a_master_stepping_two_samples_is_refused_at_its_first_connected_step(monkeypatch):
    """OMSimulator's default fixed step 1e-3 s = 2 h (docs/cosimulation.md, section 5): fmpy's
    SSP player run with it fails at its second doStep of the controller, at t = 0.001 (before
    this rule, the loop ran and the monitor stopped it at 0.105 s). The player's first doStep
    gives every input 0, its start value: nothing connected yet, so the controller holds the
    inputs over the two samples (a standalone run); at t = 0.001 t_meas has advanced."""
    import fmpy.ssp.simulation as player
    from harness.buildtime.ssp_file import parameter_set_for_scenario, write_closed_loop_ssp
    from harness.fmu import default_fmu_dir

    calls = []
    original = player.do_step

    def spy(component, time, step_size):
        calls.append((component.name, time))
        return original(component, time, step_size)

    monkeypatch.setattr(player, "do_step", spy)
    pset = parameter_set_for_scenario("mismatch_1hz")
    import tempfile
    from pathlib import Path
    with tempfile.TemporaryDirectory() as tmp:
        path = write_closed_loop_ssp(Path(tmp) / "loop.ssp", default_fmu_dir(), [pset])
        with pytest.raises(Exception):
            player.simulate_ssp(str(path), stop_time=0.2, step_size=0.001,
                                parameter_set=None)
    assert calls[-1] == ("controller", 0.001)
    assert [c for c in calls if c[0] == "controller"] == [("controller", 0.0), ("controller", 0.001)]
