"""harness.identify.data: user CSV records in, one clear line per problem.

Every bad file has its own test case with the exact message it must give (and its
exception class, all subclasses of RecordError, itself a ValueError); a good file
reads back exactly what write_record wrote (round trip, full precision).
"""
import numpy as np
import pytest

from harness.identify.data import (
    MIN_RECORD_SAMPLES,
    ConstantVoltageError,
    MissingColumnError,
    NonFiniteError,
    NonNumericError,
    RecordError,
    RecordFileError,
    SamplePeriodError,
    ShortRecordError,
    TimeGridError,
    count_reversals,
    read_record,
    write_record,
)

H = 0.0005
N = 1000


def _good(n=N, h=H):
    t = np.arange(n) * h
    return t, 10 * np.sin(2 * np.pi * 5 * t) + 10, 0.3 * np.sin(2 * np.pi * 5 * t - 0.1) + 3


def test_round_trip_is_exact_and_extra_columns_are_ignored(tmp_path):
    t, v, y = _good()
    y = y + 1e-13 * np.pi          # digits that a fixed format would lose
    path = write_record(tmp_path / "run 1.csv", t, v, y, extra={"temperature": np.full(N, 21.5)})
    assert path.read_text().splitlines()[0] == "time,v,y,temperature"
    rec = read_record(path, min_reversals=4)
    assert rec.label == "run 1" and rec.h == H and rec.n_samples == N
    assert np.array_equal(rec.time, t) and np.array_equal(rec.v, v) and np.array_equal(rec.y, y)


def test_header_order_spaces_comments_blank_lines_and_crlf(tmp_path):
    t, v, y = _good(300)
    lines = ["# exported by the DAQ", " y , note, time ,v"]
    lines += [f"{yk},x,{tk},{vk}" for tk, vk, yk in zip(t, v, y)]
    lines.insert(5, "")
    path = tmp_path / "a.csv"
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode())
    rec = read_record(path, label="mine")
    assert rec.label == "mine"
    np.testing.assert_array_equal(rec.v, v)
    np.testing.assert_array_equal(rec.y, y)


def _table(rows, header="time,v,y"):
    return header + "\n" + "\n".join(",".join(str(x) for x in r) for r in rows) + "\n"


def _rows(n=N, h=H):
    t, v, y = _good(n, h)
    return [[repr(float(a)), repr(float(b)), repr(float(c))] for a, b, c in zip(t, v, y)]


def _with(rows, line, column, value):
    """Copy of rows with one cell replaced; `line` is the file's line number (header = 1)."""
    rows = [list(r) for r in rows]
    rows[line - 2][column] = value
    return rows


# (file text, exception class, message after "<path>: ")
CASES = {
    "missing column": (_table(_rows(), "time,v,displacement"), MissingColumnError,
                       "missing column 'y'; the header has: time, v, displacement; a record needs "
                       "the columns time [s], v [V], y [um]"),
    "misnamed column": (_table(_rows(), "Time,v,y"), MissingColumnError,
                        "missing column 'time' (is 'Time' meant to be 'time'?); the header has: "
                        "Time, v, y; a record needs the columns time [s], v [V], y [um]"),
    "unit in the name": (_table(_rows(), "time,v,y [um]"), MissingColumnError,
                         "missing column 'y' (is 'y [um]' meant to be 'y'?); the header has: "
                         "time, v, y [um]; a record needs the columns time [s], v [V], y [um]"),
    "not comma-separated": ("time;v;y\n0;1;2\n", MissingColumnError,
                            "missing column 'time'; the file does not look comma-separated; the "
                            "header has: time;v;y; a record needs the columns time [s], v [V], "
                            "y [um]"),
    "repeated column": (_table(_rows(), "time,v,y,v"), RecordFileError,
                        "line 1: column 'v' appears 2 times in the header"),
    "empty file": ("\n\n", RecordFileError,
                   "the file is empty (expected a header: time,v,y)"),
    "ragged row": (_table(_rows()[:5]) + "0.0025,1\n", RecordFileError,
                   "line 7 has 2 fields, the header has 3"),
    "non-numeric": (_table(_with(_rows(), 12, 1, "12,5".replace(",", "_"))), NonNumericError,
                    "line 12, column 'v': '12_5' is not a number"),
    "hex float": (_table(_with(_rows(), 13, 2, "0x1p-3")), NonNumericError,
                  "line 13, column 'y': '0x1p-3' is not a number"),
    "empty cell": (_table(_with(_rows(), 40, 2, "")), NonNumericError,
                   "line 40, column 'y': '' is not a number"),
    "NaN": (_table(_with(_rows(), 30, 2, "nan")), NonFiniteError,
            "line 30, column 'y': nan is not finite (every value must be a finite number)"),
    "Inf": (_table(_with(_rows(), 31, 1, "-inf")), NonFiniteError,
            "line 31, column 'v': -inf is not finite (every value must be a finite number)"),
    "overflow": (_table(_with(_rows(), 32, 1, "1e999")), NonFiniteError,
                 "line 32, column 'v': 1e999 is not finite (every value must be a finite number)"),
    "time repeats": (_table(_with(_rows(), 101, 0, repr(98 * H))), TimeGridError,
                     "line 101: time does not increase (t = 0.049 s after 0.049 s)"),
    "time goes back": (_table(_with(_rows(), 3, 0, "-1.0")), TimeGridError,
                       "line 3: time does not increase (t = -1.0 s after 0.0 s)"),
    "non-uniform": (_table(_with(_rows(), 502, 0, repr(500 * H + 0.2 * H))), TimeGridError,
                    "line 502: time is not uniformly sampled: t = 0.2501 s, the uniform grid of "
                    "the record has 0.25 s (mean period 0.0005 s; tolerance 1% of it)"),
    "wrong period": (_table(_rows(h=0.001)), SamplePeriodError,
                     "sample period 0.001 s (1000 Hz) is not the model's h = 0.0005 s (2000 Hz); "
                     "record at 2000 Hz, or identify a model sampled at 0.001 s "
                     "(--sample-period 0.001)"),
    "time in ms": (_table(_rows(h=0.5)), SamplePeriodError,
                   "sample period 0.5 s (2 Hz) is not the model's h = 0.0005 s (2000 Hz) (is time "
                   "in ms? the column is in s); record at 2000 Hz, or identify a model sampled at "
                   "0.5 s (--sample-period 0.5)"),
    "one sample": (_table(_rows()[:1]), ShortRecordError,
                   "1 sample; a record needs at least 200"),
    "too few samples": (_table(_rows()[:150]), ShortRecordError,
                        "150 samples (0.075 s); a record needs at least 200 (0.1 s)"),
    "constant voltage": (_table([[r[0], "3.5", r[2]] for r in _rows()]), ConstantVoltageError,
                         "the voltage never moves (v = 3.5 V on every line); a record needs a "
                         "varying voltage"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_each_bad_file_gets_its_own_one_line_message(tmp_path, case):
    text, cls, message = CASES[case]
    path = tmp_path / "record.csv"
    path.write_text(text)
    with pytest.raises(cls) as info:
        read_record(path)
    assert str(info.value) == f"{path}: {message}"
    assert "\n" not in str(info.value)
    assert isinstance(info.value, RecordError) and isinstance(info.value, ValueError)


def test_too_few_reversals_for_a_step_that_needs_periods(tmp_path):
    t = np.arange(N) * H
    ramp = write_record(tmp_path / "ramp.csv", t, 20 * t, t)       # v moves, never reverses
    read_record(ramp)                                                # fine for a creep step
    with pytest.raises(ShortRecordError) as info:
        read_record(ramp, min_reversals=4)
    assert str(info.value) == (f"{ramp}: the voltage reverses direction 0 times; this step needs "
                               f"at least 4 (about 2 periods of a periodic input)")
    one = write_record(tmp_path / "one.csv", t, np.sin(2 * np.pi * 0.6 * t), t)
    with pytest.raises(ShortRecordError, match="reverses direction 1 time; this step"):
        read_record(one, min_reversals=4)


def test_files_that_cannot_be_read(tmp_path):
    with pytest.raises(RecordFileError) as info:
        read_record(tmp_path / "nope.csv")
    assert str(info.value) == f"{tmp_path / 'nope.csv'}: no such file"
    with pytest.raises(RecordFileError) as info:
        read_record(tmp_path)
    assert str(info.value) == f"{tmp_path}: is a folder, not a CSV file"
    binary = tmp_path / "b.csv"
    binary.write_bytes(b"time,v,y\n\xff\xfe\x00\n")
    with pytest.raises(RecordFileError, match=r"b.csv: not a text file \(invalid start byte"):
        read_record(binary)


def test_count_reversals():
    # Reference: a sine of P periods starting at its mean reverses 2P times; noise inside the
    # deadband (1 % of the range) does not count; a step or ramp never reverses.
    t = np.arange(20000) * H
    assert count_reversals(10 * np.sin(2 * np.pi * t) + 10) == 20
    noisy = 10 * np.sin(2 * np.pi * 3 * t) + 0.05 * np.sin(2 * np.pi * 900 * t)
    assert count_reversals(noisy) == 60
    assert count_reversals(np.r_[np.zeros(10), np.ones(100)]) == 0
    assert count_reversals(np.arange(100.0)) == 0
    assert MIN_RECORD_SAMPLES == 200
