"""Every field of a restored state, tampered with, is refused or is harmless by a stated reason.

A deserialized FMU state is untrusted input: the FMU restores it only if the core's checks pass
(``piezo_controller_check`` and ``piezo_controller_check_params`` against the FMU's parameters,
the controller's sample count against the FMU's: ``model_check_data`` in
``fmu_src/AdaptiveCompoundController/model.c``; ``piezo_plant_check`` and
``piezo_plant_check_params`` for the stage). Those checks are hand-written lists of fields, and the
fuzzer once found two omissions in them. Here cffi lists the structs' fields themselves (every leaf
of ``piezo_controller``, its supervisor, hysteresis and creep models included, and of
``piezo_plant``; of an array its first and last element), so a field added later is tampered with
without anyone listing it: each is set to NaN, +Inf and -Inf (doubles) or far out of range
(integers), on live states of several kinds, and the checks must refuse it, or the field must be in
``HARMLESS`` with the reason a live run, or the loop, cannot be hurt by it.
"""

from __future__ import annotations

import math
import re

import pytest

from harness.binding import core

FFI, LIB = core.ffi, core.lib()
H = 0.0005

#: values far outside what a live state holds, by the field's C type
BIG_UNSIGNED = 2 ** 62          # a sample count no run reaches (2^62 h = 73 million years)
BIG_SIGNED = 10 ** 6            # an int field: flags, codes, small counts, indices


def bad_values(ctype):
    """The values each field of that cffi type is tampered with."""
    name = ctype.cname
    if name in ("double", "float"):
        return [math.nan, math.inf, -math.inf]
    if name in ("uint64_t", "size_t", "unsigned long", "unsigned long long"):
        return [BIG_UNSIGNED]
    if name.startswith("uint") or name.startswith("unsigned"):
        return [2 ** 31]
    return [-BIG_SIGNED, BIG_SIGNED]


def leaves(ctype, prefix=""):
    """(path, cffi type) of every scalar field of a struct type, into nested structs and arrays
    (an array: its first and last element, which bound the loops the checks run over it)."""
    for name, field in ctype.fields:
        t, path = field.type, prefix + name
        if t.kind == "struct":
            yield from leaves(t, path + ".")
        elif t.kind == "array":
            for i in sorted({0, t.length - 1}):
                if t.item.kind == "struct":
                    yield from leaves(t.item, f"{path}[{i}].")
                elif t.item.kind == "array":
                    for j in sorted({0, t.item.length - 1}):
                        yield f"{path}[{i}][{j}]", t.item.item
                else:
                    yield f"{path}[{i}]", t.item
        elif t.kind == "primitive":
            yield path, t


def _text(p):
    return None if p == FFI.NULL else FFI.string(p).decode()


#: (a regular expression of the path, the tampered values it covers as a predicate, why that is
#: harmless). Anything a test state accepts must match one of these.
HARMLESS = [
    (r"(inv_creep|creep)\.soe_state\[\d+\]", lambda v: math.isinf(v),
     "a creep state overflows to +-Inf in a live advance (piezo_creep.h, piezo_gl_check); NaN is refused"),
    (r"verdict\.(?!fault$)\w+", lambda v: True,
     "the recorded verdict's evidence is text: only the messages read it (piezo_controller_explain.c, "
     "piezo_supervisor_explain.c), never as an index or in the loop; its fault code is checked"),
    (r"rng\.s\[\d+\]", lambda v: True,
     "every xoshiro256** state but all zeros lies on its one cycle, so a live generator reaches it"),
    (r"sensor_seed", lambda v: True,
     "the stage's sensor.seed as given: it seeded rng.s at the start and is not read again"),
]


def harmless(path, value):
    return next((why for pattern, covers, why in HARMLESS if re.fullmatch(pattern, path) and covers(value)),
                None)


def closed_loop(ctrl=None, n=2000, meas=None):
    """A core loop of n samples of a 5 Hz, 10 um tone: (controller, plant, their parameters)."""
    plant_params, ctrl_params = {}, dict(ctrl or {})
    p, c, v = core.Plant(plant_params), core.Controller(ctrl_params), 0.0
    for k in range(n):
        y = p.output.y_meas
        try:
            c.step(10.0 * math.sin(2 * math.pi * 5.0 * (k + 2) * H), meas(y, k) if meas else y)
        except core.CoreFaultError:
            break
        p.step(v)
        v = c.raw.out.v
    return c, p, ctrl_params, plant_params


STATES = {
    "robust law, tracking": dict(),
    "paper's law": dict(ctrl={"rls.robust": False, "rls.forgetting": 0.995, "mv.integral": 0.0,
                              "mv.observer": 0.4}),
    "delay being detected": dict(n=3),
    "safe state": dict(ctrl={"sup.reaction": 1}, meas=lambda y, k: -y if k >= 1000 else y),
}


def controller_refusal(raw, params, k):
    """What the FMU's restore says of a controller state (model_check_data's three checks)."""
    return (_text(LIB.piezo_controller_check(raw)) or _text(LIB.piezo_controller_check_params(raw, params))
            or (None if raw.k == k else "sample counter differs from the FMU's"))


def accepted_fields(ctype, raw, refusal):
    """{path: [values]} of the tampered copies of raw that refusal() accepts and HARMLESS does not
    cover; refusal(copy) is None for a state that passes."""
    size = FFI.sizeof(ctype)
    assert refusal(raw) is None, refusal(raw)
    found, n = {}, 0
    for path, t in leaves(FFI.typeof(ctype)):
        for value in bad_values(t):
            copy = FFI.new(ctype + " *")
            FFI.memmove(copy, raw, size)
            exec(f"copy.{path} = value", {"copy": copy, "value": value})
            n += 1
            if refusal(copy) is None and harmless(path, value) is None:
                found.setdefault(path, []).append(value)
    return found, n


@pytest.mark.parametrize("state", list(STATES))
def test_every_tampered_controller_field_is_refused_or_harmless(state):
    """Reference: the FMU's restore checks (model_check_data: piezo_controller_check,
    piezo_controller_check_params against the controller's own parameters, and its k against the
    FMU's) over every leaf field cffi lists, on a live state of each kind (tracking under the robust
    law, under the paper's law, while the delay is detected, in the safe state): each NaN, +-Inf or
    far out-of-range value is refused, or HARMLESS names why it is not a state to refuse."""
    c, _, ctrl_params, _ = closed_loop(**STATES[state])
    raw = c.raw
    kind = {"delay being detected": raw.detecting == 1, "safe state": raw.fault != 0}.get(state, raw.fault == 0)
    assert kind, state
    params = core.controller_params_struct(ctrl_params)
    found, n = accepted_fields("piezo_controller", raw, lambda x: controller_refusal(x, params, raw.k))
    assert n >= 688, n              # every field of the controller and its blocks (688 copies today)
    assert found == {}, found


def test_every_tampered_plant_field_is_refused_or_harmless():
    """Reference: the stage's restore checks (piezo_plant_check, piezo_plant_check_params against
    its parameters, its k against the FMU's) over every leaf field of piezo_plant after 1 s of
    the loop."""
    _, p, _, plant_params = closed_loop()
    raw = p.raw
    params = core.plant_params_struct(plant_params)
    refusal = lambda x: (_text(LIB.piezo_plant_check(x)) or _text(LIB.piezo_plant_check_params(x, params))  # noqa: E731
                         or (None if x.k == raw.k else "sample counter differs from the FMU's"))
    found, n = accepted_fields("piezo_plant", raw, refusal)
    assert n >= 128, n              # every field of the stage (128 copies today)
    assert found == {}, found


def test_the_field_list_reaches_fields_added_to_nested_blocks():
    """Reference: the struct layouts of the headers. The walk reaches the supervisor's, the
    hysteresis models' and the creep's fields, and the safe state's, by their paths."""
    paths = {p for p, _ in leaves(FFI.typeof("piezo_controller"))}
    for path in ("sup.followed_gain", "sup.yhat_slow", "inv_creep.soe_state[0]", "fwd_pi.z[0]", "fault",
                 "k_fault", "verdict.gain", "theta[3]", "P[15]"):
        assert path in paths, path
