"""resources/start_values: the FMU binary applies the start values it ships (fmu_start_values.c).

A parameterised FMU declares other start values than the compiled defaults; an
importer need not set them, so the binary reads resources/start_values at
fmi2Instantiate and applies it, again after fmi2Reset. Checked here through the
FMI API of the built binaries (fmpy's FMU2Slave, raw fmi2Instantiate for the
resource-location variants):

* values of every type land in the instance and survive fmi2Reset; the run
  equals one with the same values set through fmi2SetXXX, bit for bit;
* no file, no or an unreadable resource location: the compiled defaults;
* every malformed file is refused at instantiation with an error naming the
  file, the line and the problem;
* the file URI is decoded: file:///, file://localhost/, file:/, %XX escapes,
  a trailing slash, a query.
"""
import ctypes
import pathlib
import shutil
import urllib.parse

import numpy as np
import pytest

import conftest

H = 0.0005


class _Package:
    """An unzipped FMU in a folder of our own (so that resources/ can be written)."""

    def __init__(self, source, folder):
        self.md = source.md
        self.variables = source.variables
        self.unzipdir = str(folder)
        shutil.copytree(source.unzipdir, folder)
        self.resources = pathlib.Path(folder, "resources")
        self.resources.mkdir(exist_ok=True)

    def write(self, text, mode="w"):
        with open(self.resources / "start_values", mode) as fh:
            fh.write(text)

    def uri(self):
        return self.resources.as_uri()

    def instantiate(self, **kwargs):
        return conftest.Fmu(self, **kwargs)


@pytest.fixture
def stage_copy(piezo_stage, tmp_path):
    # a folder name that needs percent-encoding in a URI
    return _Package(piezo_stage, tmp_path / "un zip %dir#1")


@pytest.fixture
def controller_copy(controller, tmp_path):
    return _Package(controller, tmp_path / "ctrl")


class _Raw:
    """fmi2Instantiate with a resource location of our choosing; logs via the conftest dispatcher."""

    def __init__(self, package, uri):
        from fmpy import calloc, free
        from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                               fmi2CallbackFunctions, fmi2CoSimulation, fmi2False)
        from fmpy.logging import addLoggerProxy

        self.messages = []
        self.id = next(conftest._fmu_ids)
        conftest._FMU_BY_ID[self.id] = self
        md = package.md
        self.variables = package.variables
        self.slave = FMU2Slave(guid=md.guid, unzipDirectory=package.unzipdir,
                               modelIdentifier=md.coSimulation.modelIdentifier, instanceName="raw")
        cb = fmi2CallbackFunctions()
        cb.logger = conftest._shared_logger()
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        cb.componentEnvironment = self.id
        addLoggerProxy(ctypes.byref(cb))
        self.callbacks = cb
        self.slave.callbacks = cb
        self.slave.component = self.slave.fmi2Instantiate(
            b"raw", fmi2CoSimulation, md.guid.encode(), None if uri is None else uri.encode(),
            ctypes.byref(cb), fmi2False, fmi2False)

    @property
    def ok(self):
        return bool(self.slave.component)

    def get(self, name):
        var = self.variables[name]
        getter = {"Real": self.slave.getReal, "Integer": self.slave.getInteger,
                  "Boolean": self.slave.getBoolean}[var.type]
        return getter([var.valueReference])[0]

    def close(self):
        if self.slave.component:
            self.slave.fmi2FreeInstance(self.slave.component)
        self.slave.freeLibrary()
        conftest._FMU_BY_ID.pop(self.id, None)


@pytest.fixture
def raw():
    made = []

    def factory(package, uri):
        r = _Raw(package, uri)
        made.append(r)
        return r

    yield factory
    for r in made:
        r.close()


VALUES = """# written by a test
pi.m = 4
pi.w0 = 0.41
pi.w[2] = 0.05
  tf.a1=-1.442037
tf.a2 = 0.44641665\r
tf.b1 = 0.62517
tf.b2 = -0.620235
creep.k_c = 1.0497
creep.alpha = -0.0085
creep.exact = true
tf.delay = 1
sensor.seed = 7
"""
EXPECTED = {"pi.m": 4, "pi.w0": 0.41, "pi.w[1]": 0.0714, "pi.w[2]": 0.05, "tf.a1": -1.442037,
            "tf.a2": 0.44641665, "tf.b1": 0.62517, "tf.b2": -0.620235, "creep.k_c": 1.0497,
            "creep.alpha": -0.0085, "creep.exact": True, "tf.delay": 1, "sensor.seed": 7}


def _run(fmu, v):
    y = []
    for vk in v:
        y.append(fmu.get("y"))
        fmu.set({"v": vk})
        fmu.step()
    return np.array(y)


def test_values_of_every_type_are_applied_and_survive_reset(stage_copy, make_fmu):
    stage_copy.write(VALUES)
    fmu = make_fmu(stage_copy)
    assert not fmu.errors()
    fmu.setup()
    for name, value in EXPECTED.items():     # pi.w[1] is not in the file: the compiled default
        assert fmu.get(name) == value, name
    fmu.slave.exitInitializationMode()
    fmu.slave.reset()
    fmu.slave.enterInitializationMode()
    for name, value in EXPECTED.items():
        assert fmu.get(name) == value, name


def test_run_equals_the_same_values_set_through_the_api(stage_copy, piezo_stage, make_fmu):
    """Reference: the unmodified FMU with the file's values set by fmi2SetXXX: bitwise equal."""
    stage_copy.write(VALUES)
    v = 10 * np.sin(2 * np.pi * 20 * np.arange(300) * H) + 10
    parameterised = make_fmu(stage_copy)
    parameterised.initialize()
    plain = make_fmu(piezo_stage)
    plain.initialize(EXPECTED)
    default = make_fmu(piezo_stage)
    default.initialize()
    y = _run(parameterised, v)
    assert np.array_equal(y, _run(plain, v))
    assert np.max(np.abs(y - _run(default, v))) > 0.1     # the values do change the model


def test_controller_reads_its_file_too(controller_copy, make_fmu):
    controller_copy.write("pi.w0 = 0.5\nmv.delay = 1\nrls.enabled = false\n")
    fmu = make_fmu(controller_copy)
    fmu.setup()
    assert fmu.get("pi.w0") == 0.5 and fmu.get("mv.delay") == 1 and fmu.get("rls.enabled") is False


def test_without_a_file_the_compiled_defaults_stand(stage_copy, piezo_stage, make_fmu, raw):
    fmu = make_fmu(stage_copy)                  # resources/ exists, start_values does not
    fmu.setup()
    assert fmu.get("pi.w0") == 0.3344 and not fmu.errors()
    for uri in (None, ""):                     # no resource location at all
        r = raw(stage_copy, uri)
        assert r.ok and not r.messages


@pytest.mark.parametrize("text, message", [
    ("pi.w0 0.4\n", "line 1: expected 'name = value', got 'pi.w0 0.4'"),
    ("# ok\n\npi.w0 =\n", "line 3: expected 'name = value', the value is empty"),
    (" = 3\n", "line 1: expected 'name = value', the name is empty"),
    ("pi.w0 = 0.4\npi.w9 = 1\n", "line 2: 'pi.w9' is not a variable of PiezoStage"),
    ("y = 1\n", "line 1: 'y' is an output, only parameters may be given start values here"),
    ("v = 1\n", "line 1: 'v' is an input, only parameters may be given start values here"),
    ("pi.w0 = 0.4\npi.w0 = 0.5\n", "line 2: 'pi.w0' was already set on line 1"),
    ("pi.w0 = 0.4x\n", "line 1: pi.w0 = '0.4x' is not a Real number"),
    ("pi.w0 = nan\n", "line 1: pi.w0 = 'nan' is not finite"),
    ("pi.w0 = 1e999\n", "line 1: pi.w0 = '1e999' is not finite"),
    ("pi.m = 4.5\n", "line 1: pi.m = '4.5' is not an Integer"),
    ("pi.m = 99999999999\n", "line 1: pi.m = '99999999999' is outside the Integer range"),
    ("creep.exact = yes\n", "line 1: creep.exact = 'yes' is not a Boolean (true, false, 1 or 0)"),
    ("pi.w0 = 0.4\n# " + "x" * 300 + "\n", "line 2: longer than 255 characters"),
    ("pi.w0 = 0.4\npi.w[2] = 0.\x001\n", "line 2: contains a NUL byte (not a text file?)"),
])
def test_a_malformed_file_is_refused_naming_the_line(stage_copy, raw, text, message):
    stage_copy.write(text)
    r = raw(stage_copy, stage_copy.uri())
    assert not r.ok
    errors = [m for status, _, m in r.messages if status >= 3]
    assert len(errors) == 1, r.messages
    path = str(stage_copy.resources / "start_values")
    assert errors[0].startswith(f"fmi2Instantiate: start values: {path} "), errors[0]
    assert errors[0].endswith(message), errors[0]


def test_an_unreadable_file_is_refused(stage_copy, raw):
    (stage_copy.resources / "start_values").mkdir()         # exists, cannot be read as a file
    r = raw(stage_copy, stage_copy.uri())
    assert not r.ok
    (error,) = [m for status, _, m in r.messages if status >= 3]
    assert "start_values line 1: cannot be read: Is a directory" in error


def test_resource_uri_spellings(stage_copy, raw):
    stage_copy.write("pi.w0 = 0.25\n")
    folder = str(stage_copy.resources)
    quoted = urllib.parse.quote(folder)
    assert "%25" in quoted and "%20" in quoted and "%23" in quoted
    for uri in (stage_copy.uri(), "file://" + quoted, "file://localhost" + quoted,
                "FILE://LOCALHOST" + quoted, "file:" + quoted, "file://" + quoted + "/",
                "file://" + quoted + "?x=1", "file://" + quoted.replace("%2", "%2").lower()):
        r = raw(stage_copy, uri)
        assert r.ok, (uri, r.messages)
        r.slave.setupExperiment()
        r.slave.enterInitializationMode()
        assert r.get("pi.w0") == 0.25, uri
        assert not r.messages, (uri, r.messages)


@pytest.mark.parametrize("uri, why", [
    ("http://example.com/resources", "only file: URIs name a local folder"),
    ("file://otherhost/tmp/resources", "the URI names another host"),
    ("file://", "no path after the host"),
    ("file:relative/resources", "the path is not absolute"),
    ("file:///tmp/%zz/resources", "a '%' is not followed by two hexadecimal digits"),
    ("file:///tmp/%00/resources", "%00 in the path"),
])
def test_an_unusable_resource_location_warns_and_keeps_the_defaults(stage_copy, raw, uri, why):
    stage_copy.write("pi.w0 = 0.25\n")
    r = raw(stage_copy, uri)
    assert r.ok
    (warning,) = r.messages
    assert warning[0] == 1 and warning[1] == "logStatusWarning"      # fmi2Warning
    assert warning[2] == (f"fmi2Instantiate: start values: fmuResourceLocation '{uri}' is not "
                          f"read ({why}); the compiled start values are used")
    r.slave.setupExperiment()
    r.slave.enterInitializationMode()
    assert r.get("pi.w0") == 0.3344
