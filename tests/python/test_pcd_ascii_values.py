"""ASCII PCD values: each is stored as written, or the file is refused (issue 34).

PCL reads an ASCII value by stream extraction into its field's type and falls back on
atof and a cast; its stream keeps the end-of-file state of the file's first value, so
every later value goes through atof. Both ways read a prefix of what they cannot parse
and wrap what does not fit, silently. Measured with PCL 1.13 on this project's machine,
before the check of ``representation/pcd_ascii.cpp`` (``MISREAD`` gives what PCL stored
for each value as a file's first value and as a later one):

- float fields: ``0x1p3`` and ``0x10`` as 0.0 first and as 8 and 16 later, ``1e39`` as
  infinity (F 4);
- integer fields: ``1e3`` as 1 first, ``.5`` as 0, ``inf`` as -2147483648 (I 4);
- ``70000`` as 4464 in a 2-byte unsigned field, ``-1`` as 65535, ``300`` as 44 in U 1;
- a decimal within a double's rounding of the midpoint of two floats, rounded twice
  after the first value;
- 8-byte integers rounded through a double after the first value: 2^53 + 1 as 2^53,
  2^64 - 1 as 0;
- a line of white space only as a point at the origin, ``1,2,3`` as a point of zeros.

The expected values here come from the decimal text itself (Python's own parsing and
numpy's types), not from the reader under test.
"""

from __future__ import annotations

import math
import re
from decimal import Decimal, InvalidOperation

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import spectral_vs as svs

#: The integers a field takes: its type's range, to 2^53 for 8-byte fields (PCL reads all
#: but a file's first value through a double).
INTEGER_RANGES = {
    ("I", 1): (-(2**7), 2**7 - 1),
    ("I", 2): (-(2**15), 2**15 - 1),
    ("I", 4): (-(2**31), 2**31 - 1),
    ("I", 8): (-(2**53), 2**53),
    ("U", 1): (0, 2**8 - 1),
    ("U", 2): (0, 2**16 - 1),
    ("U", 4): (0, 2**32 - 1),
    ("U", 8): (0, 2**53),
}


def pcd_text(x_type: str, x_size: int, lines: list[str]) -> str:
    """A cloud of `lines` whose x field has the given TYPE and SIZE (y and z: F 4)."""
    return (
        "VERSION 0.7\nFIELDS x y z\n"
        f"SIZE {x_size} 4 4\nTYPE {x_type} F F\nCOUNT 1 1 1\n"
        f"WIDTH {len(lines)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(lines)}\n"
        "DATA ascii\n" + "".join(line + "\n" for line in lines)
    )


def load_x(tmp_path, x_type: str, x_size: int, token: str) -> float:
    """The x that `load_cloud` gives for `token` on the second line of a two-point file."""
    path = tmp_path / "value.pcd"
    path.write_text(pcd_text(x_type, x_size, ["1 2 3", f"{token} 5 6"]))
    return float(np.asarray(svs.load_cloud(path).points)[1, 0])


def written_value(token: str) -> Decimal | None:
    """The number `token` spells (decimal or hexadecimal), exactly, or None."""
    try:
        return Decimal(token)
    except InvalidOperation:
        pass
    try:
        return Decimal(float.fromhex(token))
    except ValueError:
        return None


# (TYPE, SIZE, value, what PCL 1.13 stored for it as a file's first value and as a later
# one, the message's reason). None: as written.
MISREAD = [
    ("F", 4, "0x1p3", 0.0, None, "is not a decimal number"),
    ("F", 4, "0x10", 0.0, None, "is not a decimal number"),
    ("F", 8, "0x1p3", 0.0, None, "is not a decimal number"),
    ("F", 4, "1e39", math.inf, math.inf, "is beyond the range of a 4-byte float"),
    ("F", 8, "1e400", math.inf, math.inf, "is beyond the range of a 8-byte float"),
    ("F", 4, "5e", 5.0, 5.0, "is not a decimal number"),
    # Just above the midpoint of the floats 1 and 1 + 2^-23: a double rounds it onto it.
    ("F", 4, "1.00000005960464477539062501", None, 1.0, "rounds to a different float"),
    ("F", 4, "1,", 1.0, 1.0, "is not a decimal number"),
    ("I", 4, "1e3", 1.0, None, "is not an integer"),
    ("I", 4, ".5", 0.0, 0.0, "is not an integer"),
    ("I", 4, "inf", -(2.0**31), -(2.0**31), "is not an integer"),
    ("I", 4, "nan", 0.0, 0.0, "is not an integer"),
    ("I", 4, "2147483648", -(2.0**31), -(2.0**31), r"is outside \[-2147483648, 2147483647\]"),
    ("I", 8, "9223372036854775808", -(2.0**63), -(2.0**63), r"is outside \[-9223372036854775808, "),
    ("I", 8, "9007199254740993", None, 2.0**53, r"is beyond 2\^53"),
    ("U", 8, "18446744073709551615", None, 0.0, r"is beyond 2\^53"),
    ("U", 2, "70000", 4464.0, 4464.0, r"is outside \[0, 65535\] of a 2-byte unsigned integer"),
    ("U", 2, "-1", 65535.0, 65535.0, r"is outside \[0, 65535\]"),
    ("U", 1, "300", 44.0, 44.0, r"is outside \[0, 255\] of a 1-byte unsigned integer"),
    ("U", 2, "1e3", 1.0, None, "is not an integer"),
]


@pytest.mark.parametrize(
    "x_type, x_size, token, first, later, reason",
    MISREAD,
    ids=[f"{t}{s}-{token}" for t, s, token, *_ in MISREAD],
)
def test_a_value_pcl_would_misread_is_refused_with_its_line_and_field(
    tmp_path, x_type, x_size, token, first, later, reason
):
    literal = written_value(token)
    misread = [stored for stored in (first, later) if stored is not None]
    assert misread and (literal is None or all(literal != stored for stored in misread))
    header_lines = 10
    with pytest.raises(ValueError) as error:
        load_x(tmp_path, x_type, x_size, token)
    message = str(error.value)
    assert f"line {header_lines + 2}: point 1, field 'x' (TYPE {x_type} SIZE {x_size})" in message
    assert f"'{token}' " in message
    assert re.search(reason, message), message


@pytest.mark.parametrize(
    "x_type, x_size, token, stored",
    [
        ("F", 4, "1.5", 1.5),
        ("F", 4, "-.25", -0.25),
        ("F", 4, "+3", 3.0),
        ("F", 4, "1.", 1.0),
        ("F", 4, "2.5E-3", float(np.float32(2.5e-3))),
        ("F", 4, "1e-50", 0.0),  # underflow rounds to zero, as float32 holds it
        ("F", 4, "3.4028234e38", float(np.finfo(np.float32).max)),
        ("F", 8, "0.1", 0.1),
        ("F", 8, "1e-400", 0.0),
        ("I", 1, "-128", -128.0),
        ("I", 2, "+32767", 32767.0),
        ("I", 4, "-2147483648", -(2.0**31)),
        ("I", 4, "010", 10.0),  # decimal, not octal
        ("U", 1, "255", 255.0),
        ("U", 2, "65535", 65535.0),
        ("U", 2, "-0", 0.0),
        ("U", 4, "4294967295", 4294967295.0),
        ("I", 8, "-9007199254740992", -(2.0**53)),
        ("U", 8, "9007199254740992", 2.0**53),
    ],
)
def test_a_value_within_its_type_loads_as_written(tmp_path, x_type, x_size, token, stored):
    assert load_x(tmp_path, x_type, x_size, token) == stored


@pytest.mark.parametrize("token", ["nan", "NaN", "-nan", "inf", "-Infinity"])
def test_a_non_finite_float_value_drops_its_point_and_is_counted(tmp_path, token):
    path = tmp_path / "non_finite.pcd"
    path.write_text(pcd_text("F", 4, ["1 2 3", f"{token} 5 6", "7 8 9"]))
    cloud, info = svs.load_cloud_with_info(path)
    np.testing.assert_array_equal(np.asarray(cloud.points), [[1, 2, 3], [7, 8, 9]])
    assert (info.points_in_file, info.non_finite_dropped) == (3, 1)


@pytest.mark.parametrize(
    "line, reason",
    [
        ("   ", "point 1 has 0 values"),  # PCL stored a point at the origin
        ("\t", "point 1 has 0 values"),
        ("4,5,6", "point 1 has 1 values"),  # PCL stored a point of zeros
    ],
)
def test_a_line_pcl_would_read_as_a_point_of_zeros_is_refused(tmp_path, line, reason):
    path = tmp_path / "line.pcd"
    path.write_text(pcd_text("F", 4, ["1 2 3", line, "7 8 9"]))
    with pytest.raises(ValueError, match=f"line 12: {reason}, the header gives 3"):
        svs.load_cloud(path)


def test_an_empty_line_between_points_is_skipped_as_pcl_skips_it(tmp_path):
    path = tmp_path / "empty_line.pcd"
    path.write_text(pcd_text("F", 4, ["1 2 3", "", "7 8 9"]).replace("POINTS 3", "POINTS 2"))
    path.write_text(path.read_text().replace("WIDTH 3", "WIDTH 2"))
    np.testing.assert_array_equal(np.asarray(svs.load_cloud(path).points), [[1, 2, 3], [7, 8, 9]])


def test_a_viewpoint_in_hexadecimal_is_refused(tmp_path):
    path = tmp_path / "viewpoint.pcd"
    path.write_text(pcd_text("F", 4, ["1 2 3"]).replace("VIEWPOINT 0 0 0", "VIEWPOINT 0x1p3 0 0"))
    with pytest.raises(ValueError, match="VIEWPOINT must be 7 decimal numbers"):
        svs.load_cloud(path)


def test_padding_fields_are_not_read(tmp_path):
    """PCL skips the values of a field named '_' (binary padding): so does the check."""
    path = tmp_path / "padding.pcd"
    path.write_text(
        "VERSION 0.7\nFIELDS x _ y z\nSIZE 4 1 4 4\nTYPE F U F F\nCOUNT 1 3 1 1\n"
        "WIDTH 1\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA ascii\n1 x y z 2 3\n"
    )
    np.testing.assert_array_equal(np.asarray(svs.load_cloud(path).points), [[1, 2, 3]])


@settings(derandomize=True, database=None, deadline=None, max_examples=80)
@given(data=st.data(), kind=st.sampled_from(sorted(INTEGER_RANGES)))
def test_every_integer_of_every_type_loads_exactly_and_one_past_is_refused(
    tmp_path_factory, data, kind
):
    low, high = INTEGER_RANGES[kind]
    value = data.draw(st.one_of(st.sampled_from([low, high, 0]), st.integers(low, high)))
    folder = tmp_path_factory.mktemp("integers")
    # float64 holds integers to 2^53: compare there, or through the exact float of the value.
    assert load_x(folder, *kind, str(value)) == float(value)
    for outside in (low - 1, high + 1):
        with pytest.raises(ValueError, match=r"is outside|is beyond 2\^53"):
            load_x(folder, *kind, str(outside))


@settings(derandomize=True, database=None, deadline=None, max_examples=80)
@given(bits=st.integers(0, 2**32 - 1))
def test_every_finite_float32_loads_bit_exact_from_its_shortest_decimal(tmp_path_factory, bits):
    value = np.array([bits], np.uint32).view(np.float32)[0]
    if not np.isfinite(value):
        return
    text = (
        np.format_float_positional(value, unique=True, trim="-") if bits % 2 else repr(float(value))
    )
    folder = tmp_path_factory.mktemp("floats")
    assert np.float32(load_x(folder, "F", 4, text)) == value
