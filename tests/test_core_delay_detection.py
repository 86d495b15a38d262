"""The controller's timing in the C core (piezo_controller.h, docs/cosimulation.md): the loop
delay it detects, the start-up law it runs meanwhile, the probes, the restart, and the
stamped preview it aligns with the delay it runs.

The loops are closed here on the core (harness.binding.core): the schedule of a master is a delay
line between the controller's v and the plant, and a shift of the measurement it sees, so
the true loop delay of every case is known by construction (the independent reference).
"""

import numpy as np
import pytest
from scipy import signal

from harness.binding import core
from harness.scenarios import get_scenario
import numpy_reference as ref

H = 0.0005
D = ref.DOC_DEFAULTS
PREVIEW = 4
# (loop delay of the schedule, measurement ahead of the controller's time, reference
# stepped before the controller): what each master does (docs/cosimulation.md, section 2)
SCHEDULES = {"exchange": (2, 0, 0), "seq R,C,P": (1, 0, 1), "seq C,P,R": (1, 0, 0),
             "seq P,C,R": (1, 1, 0), "seq R,P,C": (1, 1, 1)}


def closed_loop(scenario, schedule, tf_delay=0, *, signal_fn=None, ctrl_params=None, n=None,
                switch=None):
    """Run the core loop of `scenario` (its mismatched plant) under a master schedule.

    The controller's v reaches the plant d_sched - 1 samples after it is computed (a queue);
    with o = 1 the plant steps first, so the controller sees y_meas one sample newer than
    its own time and its v acts from the next step. The stamped preview is y_d at the
    measurement's sample + PREVIEW + r - o, as ReferenceSignal's (t_preview - t_meas) / h
    says; y_ref = y_d(k + 2 + r), as ReferenceSignal's lead 2 gives it. `switch` =
    (k, schedule) changes the schedule at sample k. Returns (y, y_d, outputs)."""
    sc = get_scenario(scenario)
    n = n or sc.n_samples
    plant = core.Plant({**sc.plant, "tf.delay": tf_delay})
    ctrl = core.Controller({**sc.controller, **(ctrl_params or {})})
    t = np.arange(n + 40) * H
    y_d = signal_fn(t) if signal_fn is not None else sc.signal.evaluate(t)
    d_sched, o, r = SCHEDULES[schedule]
    queue = [0.0] * (d_sched - 1)
    y, outs, v_last = np.zeros(n), [], 0.0
    for k in range(n):
        if switch is not None and k == switch[0]:
            d_sched, o, r = SCHEDULES[switch[1]]
            queue = queue[len(queue) - (d_sched - 1):] if d_sched > 1 else []
        y[k] = plant.output.y
        if o:                   # the plant steps first with the controller's last v
            plant.step(v_last)
        lead = PREVIEW + r - o
        out = ctrl.step_input(y_d[k + 2 + r], plant.output.y_meas, y_d[k + o + lead], lead)
        outs.append(out)
        v_last = out.v
        if not o:
            queue.append(out.v)
            plant.step(queue.pop(0))
    # the state a deserialized FMU state must also pass (piezo_controller_check)
    assert core.lib().piezo_controller_check(ctrl.raw) == core.ffi.NULL
    return y, y_d[:n], outs


def e_rms(y, y_d, window=slice(2000, 6000)):
    return float(np.sqrt(np.mean((y[window] - y_d[window]) ** 2)))


@pytest.mark.parametrize("tf_delay", [0, 1])
@pytest.mark.parametrize("schedule", list(SCHEDULES))
def test_the_loop_delay_of_every_schedule_is_detected_within_five_samples(schedule, tf_delay):
    """Reference: the loop delay of the schedule by construction (d_sched + tf.delay). The
    default controller (mv.delay = -1) reports 0 while detecting, chooses that d by sample 5
    (2.5 ms), and tracks the mismatch case's 1/10/20 Hz mix within 3 nm rms
    over [1, 3) s."""
    y, y_d, outs = closed_loop("mismatch_1_10_20hz", schedule, tf_delay)
    delays = np.array([o.delay for o in outs])
    want = SCHEDULES[schedule][0] + tf_delay
    chosen = int(np.flatnonzero(delays)[0])
    print(f"\n{schedule}, tf.delay {tf_delay}: d = {delays[-1]} chosen at sample {chosen}, "
          f"e_rms {e_rms(y, y_d) * 1e3:.2f} nm")
    assert np.all(delays[:chosen] == 0) and np.all(delays[chosen:] == want)
    assert chosen <= 5
    assert outs[-1].preview            # the law uses the stamped preview
    assert e_rms(y, y_d) <= 3e-3


def test_start_up_law_is_stable_for_each_delay_and_the_plain_law_is_not():
    """Reference: the closed-loop characteristic polynomial A F + z^-d B Gd of the MV law
    designed for d_c = 2 on a loop of delay d (numpy.roots, the nominal model): with the
    start-up law's observer t = 0.9 every root lies inside the unit circle for d = 1, 2, 3;
    with t = 0 (the plain law) the wrong d have roots outside (2.44 for d = 1). The core
    agrees: the law set to d = 2, t = 0.9, adaptation off, stays bounded in loops of d = 1
    and 3 of the mismatch plant, while t = 0 is declared unstable by the monitor."""
    a = [1.0, D["tf.a1"], D["tf.a2"]]
    b = [D["tf.b1"], D["tf.b2"]]

    def largest_root(t, d):
        e, g = ref.diophantine(a, 2, t)
        f = np.convolve(b, e)
        af, bg = np.convolve(a, f), np.r_[np.zeros(d), np.convolve(b, g)]
        poly = np.zeros(max(af.size, bg.size))               # coefficients of z^0, z^-1, ...
        poly[:af.size] += af
        poly[:bg.size] += bg
        roots = np.roots(poly)
        roots = roots[np.abs(roots - 0.992106) > 1e-3]      # B's zero, cancelled by the law
        return np.max(np.abs(roots))

    for d in (1, 2, 3):
        assert largest_root(0.9, d) < 0.95, d
    assert largest_root(0.0, 1) > 2.4 and largest_root(0.0, 3) > 1.4
    # a law set to the wrong d on purpose: the supervision, which says so at once, is off
    start_up = {"mv.delay": 1, "mv.observer": 0.9, "rls.enabled": False, "sup.enabled": False}
    for schedule, tf_delay in (("seq R,C,P", 0), ("exchange", 1)):
        y, y_d, _ = closed_loop("mismatch_5hz", schedule, tf_delay, ctrl_params=start_up, n=4000)
        assert np.max(np.abs(y - y_d)) < 2.0, schedule           # bounded (um)
        with pytest.raises(core.CoreUnstableError):
            closed_loop("mismatch_5hz", schedule, tf_delay, n=4000,
                        ctrl_params={**start_up, "mv.observer": 0.0})


@pytest.mark.parametrize("name, fn", [
    ("smooth start 5 (1 - cos 2 pi t)", lambda t: 5 * (1 - np.cos(2 * np.pi * t))),
    ("zero", lambda t: 0 * t),
    ("at rest for 0.5 s", lambda t: np.where(t < 0.5, 0.0, 10 * np.sin(2 * np.pi * 5 * (t - 0.5)))),
])
@pytest.mark.parametrize("schedule", ["exchange", "seq P,C,R"])
def test_a_reference_that_tells_nothing_is_answered_by_a_probe(name, fn, schedule):
    """Reference: the documented rule (docs/cosimulation.md): a trial of 20 samples that
    chooses nothing is followed by one whose first two samples add the doublet +p, -p to q.
    With these references the first trial cannot choose (no kink in q at the start); the
    choice comes in the second trial (samples 20..39), and it is the schedule's d. The
    probe is what q shows on top of the twin run without it: a twin controller fed the same
    inputs until sample 20 and peeked there gives q - p."""
    y, y_d, outs = closed_loop("mismatch_1hz", schedule, signal_fn=fn, n=3000)
    delays = np.array([o.delay for o in outs])
    chosen = int(np.flatnonzero(delays)[0])
    assert 20 <= chosen < 40, chosen
    assert delays[-1] == SCHEDULES[schedule][0]
    assert e_rms(y, y_d, slice(2000, 3000)) <= 3e-3


def test_the_probe_is_the_doublet_of_the_documented_size():
    """Reference: the rule p = 20 rms(e_best) / b1 (nominal b1), e_best the a-priori errors
    of the leading candidate over the first trial, clamped to [1e-3, 1] um, and the start-up
    law (nominal model, d = 2, T = 1 - 0.9 z^-1) from numpy_reference.diophantine. Zero
    inputs: the errors are 0, so p = 1e-3 um; the law gives q = 0 until the probe, so
    q(20) = p, and q(21) = -p plus the law's answer to q(20) = p, -(f1 / f0) p with
    F = B E; from q(22) on the law alone acts."""
    ctrl = core.Controller({"monitor.divergence_samples": 0})
    qs = [ctrl.step(0.0, 0.0).q for _ in range(23)]
    assert qs[:20] == [0.0] * 20
    assert ctrl.raw.det_trial == 20 and ctrl.raw.det_probe == 1e-3
    e, _ = ref.diophantine([1.0, D["tf.a1"], D["tf.a2"]], 2, 0.9)
    f = np.convolve([D["tf.b1"], D["tf.b2"]], e)
    assert qs[20] == 1e-3
    assert qs[21] == pytest.approx(-(f[1] / f[0]) * 1e-3 - 1e-3, rel=1e-12)
    assert qs[22] == pytest.approx(-(f[1] * qs[21] + f[2] * qs[20]) / f[0], rel=1e-12)


def test_probes_stop_after_eight():
    """Reference: the documented rule (docs/cosimulation.md, section 3.1): a detection sends
    at most 8 probes, each at least twice the one before up to the bound of 1 um, the first
    1e-3 um (zero inputs: nothing answers, the errors are the law's own echo), starting the
    trials at samples 20, 40, ..., 160; then its trials go on without probes. Driven open loop with zero inputs,
    the probe amplitude is 0 from sample 180 on and the controller is still detecting
    (supervision off: it would rightly stop a loop whose measurement never answers)."""
    ctrl = core.Controller({"monitor.divergence_samples": 0, "sup.enabled": False})
    by_trial = {}
    for k in range(400):
        ctrl.step(0.0, 0.0)
        by_trial[int(ctrl.raw.det_trial)] = ctrl.raw.det_probe
    assert sorted(by_trial) == [20 * i for i in range(21)]
    sent = [by_trial[20 * i] for i in range(1, 9)]
    assert sent[0] == 1e-3 and all(b >= min(2 * a, 1.0) and b <= 1.0 for a, b in zip(sent, sent[1:]))
    assert all(by_trial[20 * i] == 0.0 for i in range(9, 20))
    assert ctrl.raw.det_probes == 8 and ctrl.output.delay == 0


@pytest.mark.parametrize("law", ["robust", "paper"])
def test_a_master_that_changes_its_schedule_is_followed(law):
    """Reference: the true delay by construction: exchange (d = 2) up to sample 2000, then
    true Gauss-Seidel (d = 1); the loop tracks again (e_rms over [2, 3) s within 3 nm) and the
    monitor does not stop the run. Under the paper's law the chosen d = 2 is then wrong:
    |pred_error| stays above monitor.pred_error_max for 10 samples, detection restarts (the
    start-up law) and chooses d = 1 within 30 samples. Under the robust law the sample the
    master removed makes a one-sample error of about 1.1 um, beyond monitor.pred_error_max: the
    one-sample fallback (docs/model.md, estimates with guarantees, item 3) puts the nominal
    model back, whose d = 2 prediction no longer holds, so the detection restarts there too and
    chooses d = 1 within 30 samples (before that fallback the estimates absorbed the sample and
    the law stayed on the wrong d = 2)."""
    y, y_d, outs = closed_loop("mismatch_5hz", "exchange", switch=(2000, "seq C,P,R"),
                               ctrl_params=ref.PAPER_LAW if law == "paper" else None)
    delays = np.array([o.delay for o in outs])
    changes = [(int(k) + 1, int(delays[k + 1])) for k in np.flatnonzero(np.diff(delays))]
    print(f"\nd changes (sample, d): {changes}")
    assert [d for _, d in changes] == [2, 0, 1]
    assert 2000 < changes[1][0] <= 2030 and changes[2][0] <= 2030
    assert e_rms(y, y_d, slice(4000, 6000)) <= 3e-3


@pytest.mark.parametrize("d_sched, tf_delay", [(2, 0), (1, 0), (2, 1)])
def test_the_stamped_preview_makes_the_nominal_loop_exact(d_sched, tf_delay):
    """Reference: exactness on the nominal model (docs/model.md: with the right preview the
    MV loop tracks y_d exactly; the observer only shapes the transient). Nominal plant, no
    noise, the 10 Hz tone; y_ref deliberately wrong (y_d(k)), so only the stamped preview
    (4 samples ahead) can align the reference with the delay the controller detects: after
    0.1 s, |y - y_d| <= 1e-9 um. Without the stamp, the same loop lags (error > 0.1 um).
    Integral action off: it would integrate the start-up law's transient error (the loop is
    exact only once d is chosen) and give it back over about 1 / mv.integral samples
    (measured: 1.6e-4 um after 0.1 s for d = 1 with the default 0.01)."""
    worst = []
    for lead in (PREVIEW, 0):
        plant, ctrl = core.Plant({"tf.delay": tf_delay}), core.Controller({"mv.integral": 0.0})
        y_d = 10 * np.sin(2 * np.pi * 10 * np.arange(2040) * H)
        y, queue, out = np.zeros(2000), [0.0] * (d_sched - 1), None
        for k in range(2000):
            y[k] = plant.output.y
            out = ctrl.step_input(y_d[k], plant.output.y_meas, y_d[k + lead], lead)
            queue.append(out.v)
            plant.step(queue.pop(0))
        worst.append(np.max(np.abs(y[200:] - y_d[200:2000])))
        assert out.delay == d_sched + tf_delay
    print(f"\nmax |y - y_d| after 0.1 s: stamped {worst[0]:.1e} um, y_ref = y_d(k) {worst[1]:.2f} um")
    assert worst[0] <= 1e-9
    assert worst[1] > 0.1


def test_explicit_delay_runs_no_detection():
    """Reference: docs/fmus.md (mv.delay 0..8 sets d = 1 + mv.delay). A set delay reports d
    from the first sample and starts no detection (n_detections 0); with y_ref = y_d(k + d)
    the stamped preview holds the same numbers, so the run with it equals the run without
    it, sample for sample, in every output but the `preview` flag."""
    sc = get_scenario("mismatch_1_5_10hz")
    y_d = sc.signal.evaluate(np.arange(3040) * H)
    runs = []
    for lead in (0, PREVIEW):
        plant, ctrl = core.Plant(sc.plant), core.Controller({**sc.controller, "mv.delay": 1})
        outs, v_applied = [], 0.0
        for k in range(3000):
            out = ctrl.step_input(y_d[k + 2], plant.output.y_meas, y_d[k + lead], lead)
            outs.append(tuple(out)[:9])
            plant.step(v_applied)
            v_applied = out.v
        assert ctrl.raw.n_detections == 0 and {o[8] for o in outs} == {2}
        assert ctrl.output.preview == (lead > 0)
        runs.append(outs)
    assert runs[0] == runs[1]


def test_a_preview_lead_outside_the_ring_is_refused():
    """Reference: piezo_controller.h (preview_lead 0..15). Leads -1 and 16 are refused
    (PIEZO_ERR_PARAM, nothing committed); 15 is taken."""
    ctrl = core.Controller()
    for lead in (-1, 16):
        with pytest.raises(ValueError):
            ctrl.step_input(0.0, 0.0, 1.0, lead)
        assert ctrl.k == 0
    ctrl.step_input(0.0, 0.0, 1.0, 15)
    assert ctrl.k == 1


def test_default_observer_lowers_the_noise_gain():
    """Reference: scipy.signal.dimpulse of Gd / T for the nominal A (the measurement noise
    reaches y through Gd / T, docs/model.md): its 2-norm for d = 2 falls from 1.60 (t = 0)
    to 0.96 (t = 0.4, the default). The core's Diophantine with the observer
    (piezo_diophantine_observer) satisfies T = A E + z^-d Gd to 1e-12."""
    a1, a2 = D["tf.a1"], D["tf.a2"]
    norms = {}
    for t in (0.0, 0.4):
        e = np.zeros(9)
        g = np.zeros(2)
        assert core.lib().piezo_diophantine_observer(a1, a2, t, 2, core.ffi.from_buffer("double[]", e),
                                                     core.ffi.from_buffer("double[]", g)) == 0
        total = np.polymul([1.0, a1, a2], e[:2])
        total[2:4] += g
        assert np.max(np.abs(total - [1.0, -t, 0.0, 0.0])) <= 1e-12
        _, (h,) = signal.dimpulse((g, [1.0, -t], 1), n=2000)
        norms[t] = float(np.sqrt(np.sum(h ** 2)))
    print(f"\n||Gd/T||: t = 0 {norms[0.0]:.3f}, t = 0.4 {norms[0.4]:.3f}")
    assert norms[0.0] == pytest.approx(1.60, abs=0.01) and norms[0.4] == pytest.approx(0.96, abs=0.01)
