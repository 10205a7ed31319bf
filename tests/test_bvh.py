"""BVH reader/writer: real CMU clips, format variants, round trips, precise errors, fuzzing."""

import pickle
import string

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fourierjax import data
from fourierjax.errors import FourierJaxError, UserError
from fourierjax.io import BVHError, Motion, format_bvh, parse_bvh, read_bvh, write_bvh
from fourierjax.skeleton import Skeleton, Topology

CMU_NAMES = (
    "Hips LHipJoint LeftUpLeg LeftLeg LeftFoot LeftToeBase RHipJoint RightUpLeg RightLeg "
    "RightFoot RightToeBase LowerBack Spine Spine1 Neck Neck1 Head LeftShoulder LeftArm "
    "LeftForeArm LeftHand LeftFingerBase LeftHandIndex1 LThumb RightShoulder RightArm "
    "RightForeArm RightHand RightFingerBase RightHandIndex1 RThumb"
).split()
ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")


def naive_motion_values(path):
    """Independent oracle: the MOTION rows parsed with plain Python, one token at a time."""
    with open(path, encoding="utf-8") as f:
        lines = f.read().splitlines()
    k = next(i for i, line in enumerate(lines) if line.strip() == "MOTION")
    rows = [[float(t) for t in line.split()] for line in lines[k + 3 :] if line.strip()]
    return int(lines[k + 1].split(":")[1]), float(lines[k + 2].split(":")[1]), np.array(rows)


# -- the bundled CMU clips ------------------------------------------------------------------


@pytest.mark.parametrize("name", data.list())
def test_bundled_clip_structure_and_values(name):
    path = data.path(name)
    m = read_bvh(path)
    frames, frame_time, rows = naive_motion_values(path)
    topo = m.topology
    assert topo.names == tuple(CMU_NAMES)
    assert topo.parents[0] == -1 and all(p >= 0 for p in topo.parents[1:])
    assert topo.channels[0] == ROOT_CHANNELS
    assert all(c == ("Zrotation", "Yrotation", "Xrotation") for c in topo.channels[1:])
    assert topo.rotation_orders == ("ZYX",) * 31
    assert (m.num_joints, topo.num_end_sites, topo.num_channels) == (31, 7, 96)
    assert m.num_frames == frames == rows.shape[0]
    assert m.frame_time_s == frame_time
    assert m.source == str(path)
    # Bit-exact against the token-by-token oracle, including the sign of -0.0000.
    assert m.channels.dtype == np.float64
    np.testing.assert_array_equal(m.channels, rows)
    assert np.array_equal(np.signbit(m.channels), np.signbit(rows))
    # The parent of LeftUpLeg is LHipJoint, and End Sites hang off the leaf joints.
    assert topo.parents[topo.index("LeftUpLeg")] == topo.index("LHipJoint")
    assert topo.parents[topo.index("Spine")] == topo.index("LowerBack")
    leaves = {"LeftToeBase", "RightToeBase", "Head", "LeftHandIndex1", "LThumb",
              "RightHandIndex1", "RThumb"}  # fmt: skip
    assert {topo.names[p] for p in topo.end_site_parents} == leaves


@pytest.mark.parametrize("name", data.list())
def test_bundled_clip_round_trips(name, tmp_path):
    m = read_bvh(data.path(name))
    out = tmp_path / "copy.bvh"
    write_bvh(m, out)
    back = read_bvh(out)
    assert back.topology == m.topology
    assert back.frame_time_s == m.frame_time_s
    for a, b in [(back.offsets, m.offsets), (back.end_site_offsets, m.end_site_offsets),
                 (back.channels, m.channels)]:  # fmt: skip
        np.testing.assert_allclose(a, b, rtol=0, atol=0.5e-6 + 1e-12)
    # Written again, the text is identical: writing is deterministic and stable.
    assert format_bvh(back) == out.read_text()
    # Coarser precision: equal to the printed precision.
    coarse = parse_bvh(format_bvh(m, precision=2))
    np.testing.assert_allclose(coarse.channels, m.channels, rtol=0, atol=0.005 + 1e-9)


def test_crlf_file_reports_the_same_lines_as_lf():
    text = data.path("142_02").read_bytes().decode()
    assert "\r\n" in text
    lf = text.replace("\r\n", "\n")
    a, b = parse_bvh(text), parse_bvh(lf)
    assert a.topology == b.topology
    np.testing.assert_array_equal(a.channels, b.channels)
    bad = lf.splitlines()
    bad[200] = bad[200] + " 1.0"  # line 201: one value too many
    for sep in ("\n", "\r\n", "\r"):
        with pytest.raises(BVHError) as e:
            parse_bvh(sep.join(bad), source="x.bvh")
        assert e.value.line == 201 and "97 values, expected 96" in str(e.value)


# -- format variants -------------------------------------------------------------------------

VARIANT = """\ufeffhierarchy
root  Hips {
    offset 1 2 3
  \tchannels 6 XPOSITION yposition Zposition Zrotation Xrotation Yrotation

\tJoint Left Leg
\t{
\t\tOFFSET 0.5 -4 0
\t\tCHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation Zrotation
\t\tEnd site
\t\t{
\t\t\tOFFSET 0 -4 0
\t\t}
\t}
\tJOINT Chest
\t{
\t\tOFFSET 0 5 0
\t\tCHANNELS 2 Xrotation Yrotation
\t\tJOINT Neck
\t\t{
\t\t\tOFFSET 0 1 0
\t\t\tCHANNELS 0
\t\t\tend Site { OFFSET 0 1 0 }
\t\t}
\t}
}
ROOT Prop
{
\tOFFSET 9 9 9
\tCHANNELS 3 Xposition Yposition Zposition
}

MOTION
Frames:\t2
Frame Time:   .25

1 2 3 10 20 30   4 5 6 40 50 60   70 80   7 8 9
-1 -2 -3 -10 -20 -30 -4 -5 -6 -40 -50 -60 -70 -80 -7 -8 -9\t

"""


@pytest.mark.parametrize("newline", ["\n", "\r\n", "\r"])
def test_format_variants_parse_to_the_expected_motion(newline):
    m = parse_bvh(VARIANT.replace("\n", newline))
    topo = m.topology
    assert topo.names == ("Hips", "Left Leg", "Chest", "Neck", "Prop")
    assert topo.parents == (-1, 0, 0, 2, -1)
    assert topo.channels == (
        ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"),
        ("Xposition", "Yposition", "Zposition", "Yrotation", "Xrotation", "Zrotation"),
        ("Xrotation", "Yrotation"),
        (),
        ("Xposition", "Yposition", "Zposition"),
    )
    assert topo.rotation_orders == ("ZXY", "YXZ", "XY", None, None)
    assert topo.end_site_parents == (1, 3)
    np.testing.assert_array_equal(m.offsets, [[1, 2, 3], [0.5, -4, 0], [0, 5, 0], [0, 1, 0],
                                              [9, 9, 9]])  # fmt: skip
    np.testing.assert_array_equal(m.end_site_offsets, [[0, -4, 0], [0, 1, 0]])
    row = [1, 2, 3, 10, 20, 30, 4, 5, 6, 40, 50, 60, 70, 80, 7, 8, 9]
    np.testing.assert_array_equal(m.channels, [row, [-v for v in row]])
    assert m.frame_time_s == 0.25 and m.source is None
    # ... and round-trips through the writer with canonical spelling.
    text = format_bvh(m)
    assert "XPOSITION" not in text and "\tJOINT Left Leg\n" in text and "End Site" in text
    back = parse_bvh(text)
    assert back.topology == topo
    np.testing.assert_array_equal(back.channels, m.channels)
    np.testing.assert_array_equal(back.end_site_offsets, m.end_site_offsets)


def _dfs_topology(rng, num_joints, num_end_sites):
    """Random topology in depth-first (BVH) order with mixed orders and 6-channel joints."""
    parents, path = [-1], [0]  # path: the last joint and its ancestors
    for i in range(1, num_joints):
        del path[int(rng.integers(1, len(path) + 1)) :]
        parents.append(path[-1])
        path.append(i)
    channels = []
    for i in range(num_joints):
        rot = tuple(f"{a}rotation" for a in rng.permutation(list("XYZ")))
        pos = tuple(f"{a}position" for a in rng.permutation(list("XYZ")))
        kind = rng.integers(0, 4) if i else 0
        channels.append([pos + rot, rot + pos, rot, rot[: int(rng.integers(0, 3))]][kind])
    post = {j: k for k, j in enumerate(_postorder(parents))}
    ends = sorted((int(p) for p in rng.integers(0, num_joints, num_end_sites)), key=post.get)
    return Topology(tuple(f"j{i}" for i in range(num_joints)), tuple(parents),
                    tuple(channels), tuple(ends))  # fmt: skip


def _postorder(parents):
    children = {i: [c for c, p in enumerate(parents) if p == i] for i in range(-1, len(parents))}
    out = []

    def visit(j):
        for c in children[j]:
            visit(c)
        out.append(j)

    for r in children[-1]:
        visit(r)
    return out


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 12), st.integers(0, 5), st.integers(1, 6))
def test_random_skeletons_round_trip(seed, num_joints, num_end_sites, num_frames):
    rng = np.random.default_rng(seed)
    topo = _dfs_topology(rng, num_joints, num_end_sites)
    if topo.num_channels == 0:
        return
    channels = rng.uniform(-360, 360, (num_frames, topo.num_channels))
    offsets, ends = rng.normal(size=(num_joints, 3)) * 10, rng.normal(size=(num_end_sites, 3))
    m = Motion(topo, offsets, ends, channels, float(rng.uniform(1e-3, 1)))
    back = parse_bvh(format_bvh(m, precision=8))
    assert back.topology == topo
    assert back.frame_time_s == m.frame_time_s
    np.testing.assert_allclose(back.channels, m.channels, rtol=0, atol=0.5e-8 + 1e-12)
    np.testing.assert_allclose(back.offsets, m.offsets, rtol=0, atol=0.5e-8 + 1e-12)
    np.testing.assert_allclose(back.end_site_offsets, m.end_site_offsets, rtol=0, atol=1e-8)


def test_end_sites_before_sibling_joints_keep_their_order():
    text = (
        "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\nEnd Site\n{\nOFFSET 1 0 0\n}\n"
        "JOINT b\n{\nOFFSET 0 1 0\nCHANNELS 1 Yrotation\nEnd Site\n{\nOFFSET 2 0 0\n}\n}\n"
        "End Site\n{\nOFFSET 3 0 0\n}\n}\nMOTION\nFrames: 1\nFrame Time: 1\n5 6\n"
    )
    m = parse_bvh(text)
    assert m.topology.end_site_parents == (0, 1, 0)
    back = parse_bvh(format_bvh(m))
    assert back.topology == m.topology
    np.testing.assert_array_equal(back.end_site_offsets[:, 0], [1, 2, 3])


def test_writer_rejects_what_bvh_cannot_hold():
    topo = Topology(("a", "b", "c", "d"), (-1, 0, 0, 1), (("Xrotation",),) * 4)  # not DFS
    m = Motion(topo, np.zeros((4, 3)), np.zeros((0, 3)), np.zeros((1, 4)), 0.1)
    with pytest.raises(UserError, match="depth-first"):
        format_bvh(m)
    good = Topology(("a", "b"), (-1, 0), (("Xrotation",),) * 2)
    m = Motion(good, np.zeros((2, 3)), np.zeros((0, 3)), np.zeros((2, 2)), 0.1)
    with pytest.raises(UserError, match="no frames"):
        format_bvh(m[2:])
    with pytest.raises(UserError, match="NaN"):
        format_bvh(m.with_channels(np.full((1, 2), np.nan)))
    with pytest.raises(UserError, match="precision"):
        format_bvh(m, precision=-1)
    spaced = Topology(("a", "b  c"), (-1, 0), (("Xrotation",),) * 2)
    with pytest.raises(UserError, match="cannot be written"):
        format_bvh(Motion(spaced, np.zeros((2, 3)), np.zeros((0, 3)), np.zeros((1, 2)), 0.1))


# Up to 15 digits (the exact path's bound) and below MAX_ABS_VALUE (1e6); 16 digits take the
# generic path.
DECIMAL_TOKEN = st.from_regex(r"\A[+-]?([0-9]{1,6}(\.[0-9]{0,9})?|\.[0-9]{1,9})\Z")
ANY_TOKEN = DECIMAL_TOKEN | st.sampled_from(["1e3", "-2.5E-2", "1" * 6 + "." + "1" * 10,
                                             "0." + "3" * 15,
                                             "+.5", "-0", "-0.000", "007.50"])  # fmt: skip


@settings(max_examples=60, deadline=None)
@given(st.lists(st.lists(ANY_TOKEN, min_size=3, max_size=3), min_size=1, max_size=8))
def test_values_equal_python_float_bit_for_bit(rows):
    """The vectorised decimal path and the generic fallback both give float(token) exactly."""
    header = "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yrotation Zrotation\n}\n"
    body = "\n".join(" ".join(r) for r in rows)
    m = parse_bvh(f"{header}MOTION\nFrames: {len(rows)}\nFrame Time: 0.1\n{body}\n")
    expected = np.array([[float(t) for t in r] for r in rows])
    assert np.array_equal(m.channels.view(np.int64), expected.view(np.int64))


# -- Motion ----------------------------------------------------------------------------------


def test_motion_api():
    m = data.load("07_01", raw=True)
    assert m.num_frames == 317 and m.num_joints == 31 and len(m) == 317
    assert m.duration_s == pytest.approx(317 * 0.0083333)
    assert m.fps == pytest.approx(1 / 0.0083333)
    sub = m[10:20]
    np.testing.assert_array_equal(sub.channels, m.channels[10:20])
    assert sub.topology is m.topology and sub.frame_time_s == m.frame_time_s
    half = m[::2]
    assert half.num_frames == 159 and half.frame_time_s == 2 * m.frame_time_s
    with pytest.raises(TypeError, match="slice"):
        m[3]
    with pytest.raises(TypeError):
        m[[1, 2]]
    new = m.with_channels(np.zeros((5, 96)))
    assert new.num_frames == 5 and new.topology == m.topology
    np.testing.assert_array_equal(new.offsets, m.offsets)
    with pytest.raises(UserError, match="96"):
        m.with_channels(np.zeros((5, 95)))
    with pytest.raises(UserError, match="frame_time_s"):
        Motion(m.topology, m.offsets, m.end_site_offsets, m.channels, 0.0)
    with pytest.raises(UserError, match="frame_time_s"):  # as the parser: fps would be inf
        Motion(m.topology, m.offsets, m.end_site_offsets, m.channels, 1e-320)
    with pytest.raises(ValueError, match="offsets"):
        Motion(m.topology, m.offsets[:3], m.end_site_offsets, m.channels, 0.1)
    with pytest.raises(ValueError):  # frozen, read-only arrays: safe to share and cache
        m.channels[0, 0] = 1.0
    assert "31 joints" in repr(m) and "317 frames" in repr(m)


def test_motion_skeleton():
    m = data.load("02_01")
    skel = m.skeleton()
    assert isinstance(skel, Skeleton) and skel.topology == m.topology
    assert str(skel.offsets.dtype) == "float32"
    np.testing.assert_allclose(np.asarray(skel.offsets), m.offsets, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(skel.end_site_offsets), m.end_site_offsets, rtol=1e-6)


# -- errors ----------------------------------------------------------------------------------

BASE = """HIERARCHY
ROOT Hips
{
\tOFFSET 0 0 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
\tJOINT Chest
\t{
\t\tOFFSET 0 5 0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 3 0
\t\t}
\t}
}
MOTION
Frames: 3
Frame Time: 0.0333333
0 1 2 3 4 5 6 7 8
1 1 2 3 4 5 6 7 8
2 1 2 3 4 5 6 7 8
"""


def _edit(line, new):
    """BASE with 1-based `line` replaced by `new` (None deletes it)."""
    lines = BASE.splitlines()
    if new is None:
        del lines[line - 1]
    else:
        lines[line - 1] = new
    return "\n".join(lines) + "\n"


ERRORS = [
    ("no HIERARCHY", _edit(1, "HIERARCH"), 1, "expected HIERARCHY"),
    ("empty", "", None, "empty"),
    ("blank", "\n \n\t\n", None, "empty"),
    ("no MOTION", _edit(16, None), 16, "expected ROOT or MOTION"),
    ("hierarchy only", "\n".join(BASE.splitlines()[:15]), 15, "missing MOTION"),
    ("missing }", _edit(14, None), 15, "unbalanced braces"),
    ("extra }", _edit(15, "}\n}"), 16, "expected ROOT or MOTION, found '}'"),
    ("extra {", _edit(7, "\t{ {"), 7, "unexpected '{'"),
    ("truncated hierarchy", "\n".join(BASE.splitlines()[:9]), 9, "end of file"),
    ("unknown channel", _edit(9, "\t\tCHANNELS 3 Zrotation Xrot Yrotation"), 9, "'Xrot'"),
    ("repeated channel", _edit(9, "\t\tCHANNELS 3 Zrotation Zrotation Yrotation"), 9, "twice"),
    ("channel count", _edit(9, "\t\tCHANNELS 4 Zrotation Xrotation Yrotation"), 9, "declares 4"),
    ("channel count word", _edit(9, "\t\tCHANNELS three Zrotation"), 9, "number of channels"),
    ("offset count", _edit(8, "\t\tOFFSET 0 5"), 8, "OFFSET needs 3 numbers"),
    ("offset value", _edit(8, "\t\tOFFSET 0 five 0"), 8, "'five' is not a number"),
    ("offset nan", _edit(8, "\t\tOFFSET 0 nan 0"), 8, "not a finite number"),
    ("no offset", _edit(8, None), 13, "has no OFFSET"),
    ("duplicate name", _edit(6, "\tJOINT Hips"), 6, "joint name 'Hips' (first at line 2)"),
    ("unnamed joint", _edit(6, "\tJOINT"), 6, "without a name"),
    ("junk keyword", _edit(8, "\t\tOFSET 0 5 0"), 8, "unexpected 'OFSET'"),
    ("frames > rows", _edit(17, "Frames: 4"), 17, "'Frames: 4' but the file has 3 rows"),
    ("frames < rows", _edit(17, "Frames: 2"), 17, "has 3 rows"),
    ("zero frames", _edit(17, "Frames: 0"), 17, "zero frames"),
    ("huge frames", _edit(17, "Frames: " + "9" * 5000), 17, "not a valid count"),
    ("huge channels", _edit(9, "\t\tCHANNELS " + "3" * 5000), 9, "number of channels"),
    ("negative frames", _edit(17, "Frames: -3"), 17, "not a valid count"),
    ("no Frames line", _edit(17, None), 17, "expected 'Frames: <count>'"),
    ("no Frame Time", _edit(18, None), 18, "expected 'Frame Time: <seconds>'"),
    ("zero frame time", _edit(18, "Frame Time: 0"), 18, "must be positive"),
    ("negative frame time", _edit(18, "Frame Time: -0.1"), 18, "must be positive"),
    ("nan frame time", _edit(18, "Frame Time: nan"), 18, "must be positive"),
    ("text frame time", _edit(18, "Frame Time: fast"), 18, "not a number"),
    ("short row", _edit(20, "1 1 2 3 4 5 6 7"), 20, "frame 1 has 8 values, expected 9"),
    ("long row", _edit(21, "2 1 2 3 4 5 6 7 8 9"), 21, "frame 2 has 10 values"),
    ("non-numeric", _edit(20, "1 1 2 3 x4 5 6 7 8"), 20, "'x4' is not a number"),
    ("two dots", _edit(21, "2 1 2 3 4 5 6.0.1 7 8"), 21, "'6.0.1' is not a number"),
    ("nan value", _edit(20, "1 1 2 3 4 NaN 6 7 8"), 20, "non-finite value nan in frame 1"),
    ("inf value", _edit(21, "2 1 2 3 4 5 6 7 -inf"), 21, "non-finite value -inf in frame 2"),
    ("control character", _edit(20, "1 1 2 3 4\x005 6 7 8"), 20, "control character"),
    ("non-ascii value", _edit(19, "0 1 2 3 4 5 6 7 8\u00b0"), 19, "unexpected character"),
    ("huge value", _edit(20, "1 1 2 3 4 1e308 6 7 8"), 20,
     "value 1e+308 in frame 1 (channel 5 Hips.Xrotation) is beyond +-1e+06"),
    ("huge decimal value", _edit(21, "2 1 2 3 4 5 6 7 -1000000.5"), 21, "is beyond +-1e+06"),
    ("huge offset", _edit(8, "\t\tOFFSET 0 1e7 0"), 8, "OFFSET: '1e7' is beyond +-1e+06"),
    ("junk in joint name", _edit(6, "\tJOINT Chest @@"), 6,
     "unexpected '@@' in the joint name 'Chest @@'"),
    ("junk in root name", _edit(2, "ROOT Hips = {"), 2, "unexpected '='"),
    ("no channels", _edit(5, "\tCHANNELS 0").replace("CHANNELS 3 Zrotation Xrotation Yrotation",
                                                      "CHANNELS 0"), 16, "no channels"),
]  # fmt: skip


@pytest.mark.parametrize("case", ERRORS, ids=[c[0] for c in ERRORS])
def test_bad_input_names_file_and_line(case):
    _, text, line, fragment = case
    with pytest.raises(BVHError) as e:
        parse_bvh(text, source="walk.bvh")
    err = e.value
    assert isinstance(err, FourierJaxError) and isinstance(err, ValueError)
    assert err.path == "walk.bvh" and err.line == line, str(err)
    assert fragment in err.message, str(err)
    assert str(err) == (f"walk.bvh:{line}: {err.message}" if line else f"walk.bvh: {err.message}")
    assert "\n" not in str(err)


def test_base_text_is_valid():
    m = parse_bvh(BASE)
    assert m.channels.shape == (3, 9) and m.topology.rotation_orders == ("ZYX", "ZXY")


def test_file_errors(tmp_path):
    missing = tmp_path / "nope.bvh"
    with pytest.raises(BVHError) as e:
        read_bvh(missing)
    assert e.value.line is None and str(e.value) == f"{missing}: no such file"
    with pytest.raises(BVHError, match="directory"):
        read_bvh(tmp_path)
    bad = tmp_path / "latin1.bvh"
    bad.write_bytes(_edit(6, "\tJOINT Ch\xe9st").encode("latin-1"))
    with pytest.raises(BVHError) as e:
        read_bvh(bad)
    assert (e.value.path, e.value.line) == (str(bad), 6) and "UTF-8" in e.value.message
    ok = tmp_path / "utf8.bvh"
    ok.write_bytes(b"\xef\xbb\xbf" + _edit(6, "\tJOINT Ch\u00e9st").encode())
    assert read_bvh(ok).topology.names == ("Hips", "Ch\u00e9st")
    with pytest.raises(TypeError):
        parse_bvh(BASE.encode())


def test_bvh_error_pickles():
    err = BVHError("a.bvh", 3, "bad")
    back = pickle.loads(pickle.dumps(err))
    assert (back.path, back.line, back.message, str(back)) == ("a.bvh", 3, "bad", "a.bvh:3: bad")


# -- fuzzing: nothing but BVHError, or a consistent Motion ------------------------------------

SEED = format_bvh(data.load("09_02")[:4])  # real skeleton, 4 frames: small and valid
SEED_LINES = SEED.splitlines()
VOCAB = ["{", "}", "ROOT", "JOINT", "End", "Site", "OFFSET", "CHANNELS", "MOTION", "Frames:",
         "Frame", "Time:", "3", "6", "0", "-1", "1e309", "nan", "1.5.2", "Xrotation", "Zposition",
         "HIERARCHY", "\n", "\r", "\t", "", "\x00", "\u00e9", "9" * 400, "7" * 5000]  # fmt: skip


def _check(parse):
    try:
        m = parse()
    except BVHError as err:
        assert err.line is None or err.line >= 1
        assert "\n" not in str(err) and "\r" not in str(err)
        return
    assert m.channels.shape == (m.num_frames, m.topology.num_channels)
    assert m.num_frames >= 1 and np.isfinite(m.channels).all()
    assert m.offsets.shape == (m.num_joints, 3) and np.isfinite(m.offsets).all()
    assert m.end_site_offsets.shape == (m.topology.num_end_sites, 3)
    assert m.frame_time_s > 0


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_fuzz_token_edits(d):
    tokens = SEED.split(" ")
    for _ in range(d.draw(st.integers(1, 4))):
        i = d.draw(st.integers(0, len(tokens) - 1))
        op = d.draw(st.sampled_from(["delete", "insert", "replace", "truncate", "dupline"]))
        if op == "delete":
            del tokens[i]
        elif op == "insert":
            tokens.insert(i, d.draw(st.sampled_from(VOCAB)))
        elif op == "replace":
            tokens[i] = d.draw(st.sampled_from(VOCAB) | st.text(string.printable, max_size=6))
        elif op == "truncate":
            del tokens[i:]
        if not tokens:
            tokens = [""]
    text = " ".join(tokens)
    if d.draw(st.booleans()):
        lines = text.split("\n")
        k = d.draw(st.integers(0, len(lines) - 1))
        lines.insert(k, lines[k])
        text = "\n".join(lines)
    _check(lambda: parse_bvh(text, source="fuzz.bvh"))


@settings(max_examples=150, deadline=None)
@given(st.data())
def test_fuzz_bytes(tmp_path_factory, d):
    raw = bytearray(SEED.replace("\n", "\r\n" if d.draw(st.booleans()) else "\n").encode())
    for _ in range(d.draw(st.integers(0, 6))):
        i = d.draw(st.integers(0, len(raw) - 1))
        op = d.draw(st.sampled_from(["flip", "delete", "insert", "cut"]))
        if op == "flip":
            raw[i] = d.draw(st.integers(0, 255))
        elif op == "delete":
            del raw[i]
        elif op == "insert":
            raw[i:i] = d.draw(st.binary(min_size=1, max_size=4))
        else:
            del raw[i:]
        if not raw:
            break
    path = tmp_path_factory.getbasetemp() / "fuzz.bvh"
    path.write_bytes(bytes(raw))
    _check(lambda: read_bvh(path))


@settings(max_examples=60, deadline=None)
@given(st.binary(max_size=300) | st.text(max_size=300))
def test_fuzz_random_input(blob):
    text = blob.decode("utf-8", "replace") if isinstance(blob, bytes) else blob
    _check(lambda: parse_bvh(text))
    one_joint = "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\n}\n"
    _check(lambda: parse_bvh(one_joint + text))
    _check(lambda: parse_bvh("\n".join(SEED_LINES[:-2]) + "\n" + text))


# -- strict numbers (audit item 13): float()'s extra spellings are not BVH numbers ------------

STRICT_NUMBER_ERRORS = [
    ("underscore value", _edit(20, "1 1_0 2 3 4 5 6 7 8"), 20, "'1_0' is not a number"),
    ("underscore exponent", _edit(21, "2 1 2 3 4 5 6 7 1e1_0"), 21, "'1e1_0' is not a number"),
    ("underscore after a bad line", _edit(20, "1 1 2 3 x4 5 6 7 8").replace("2 1 2", "2 1_0 2"),
     20, "'x4' is not a number"),
    ("underscore offset", _edit(8, "\t\tOFFSET 1_0 5 0"), 8, "OFFSET: '1_0' is not a number"),
    ("arabic-indic offset", _edit(8, "\t\tOFFSET \u0661\u0662 5 0"), 8, "is not a number"),
    ("fullwidth offset", _edit(8, "\t\tOFFSET 0 \uff15 0"), 8, "is not a number"),
    ("underscore frame time", _edit(18, "Frame Time: 0.0_1"), 18, "'0.0_1' is not a number"),
    ("arabic-indic frame time", _edit(18, "Frame Time: \u0660.\u0661"), 18, "not a number"),
    ("subnormal frame time", _edit(18, "Frame Time: 1e-320"), 18, "below the minimum 1e-06 s"),
    ("tiny frame time", _edit(18, "Frame Time: 9e-7"), 18, "below the minimum 1e-06 s"),
    ("huge frame time", _edit(18, "Frame Time: 1e300"), 18, "above the maximum 60 s"),
]  # fmt: skip


@pytest.mark.parametrize("case", STRICT_NUMBER_ERRORS, ids=[c[0] for c in STRICT_NUMBER_ERRORS])
def test_lenient_float_spellings_are_rejected(case):
    test_bad_input_names_file_and_line(case)


def test_strict_numbers_still_accept_every_bvh_spelling():
    from fourierjax.io.bvh import MIN_FRAME_TIME_S

    text = _edit(8, "\t\tOFFSET +1.5E+1 .5 -2.").replace("Frame Time: 0.0333333",
                                                          f"Frame Time: {MIN_FRAME_TIME_S!r}")
    text = text.replace("1 1 2 3 4 5 6 7 8", "1 1e1 2. .3 -4E-1 +5 6 7 8")
    m = parse_bvh(text)
    np.testing.assert_array_equal(m.offsets[1], [15.0, 0.5, -2.0])
    np.testing.assert_array_equal(m.channels[1], [1, 10, 2, 0.3, -0.4, 5, 6, 7, 8])
    assert m.frame_time_s == MIN_FRAME_TIME_S == 1e-6


def test_bvh_error_is_a_user_error():
    from fourierjax.errors import UserError

    assert issubclass(BVHError, UserError) and issubclass(BVHError, ValueError)
    with pytest.raises(UserError, match="walk.bvh:20"):
        parse_bvh(_edit(20, "1 1 2 3 x4 5 6 7 8"), source="walk.bvh")


def test_values_up_to_the_limit_and_spaced_names_are_read():
    """The rule for names: every word after JOINT is part of the name (3ds Max Biped names have
    spaces), and a word needs a letter or digit. 1e6 itself is a valid value."""
    from fourierjax.io.bvh import MAX_ABS_VALUE

    text = _edit(6, "\tJOINT Bip01 L Thigh").replace("0 1 2 3 4 5 6 7 8", "0 1 2 3 4 5 6 7 1e6")
    m = parse_bvh(text)
    assert m.topology.names == ("Hips", "Bip01 L Thigh") and m.channels[0, -1] == MAX_ABS_VALUE
    assert parse_bvh(format_bvh(m)).topology.names == m.topology.names
    assert parse_bvh(_edit(6, "\tJOINT Neck_2 (left) {").replace("\t{\n\t\tOFFSET 0 5", "\t\tOFFSET 0 5", 1)
                     ).topology.names[1] == "Neck_2 (left)"


def test_a_memory_error_while_reading_becomes_a_bvh_error(monkeypatch, tmp_path):
    from fourierjax.io import _bvh_parse

    def no_memory(*args, **kwargs):
        raise MemoryError

    path = tmp_path / "walk.bvh"
    path.write_text(BASE)
    monkeypatch.setattr(_bvh_parse, "_parse_motion_block", no_memory)
    with pytest.raises(BVHError) as e:
        read_bvh(path)
    assert (e.value.path, e.value.line) == (str(path), 17) and "not enough memory" in str(e.value)
