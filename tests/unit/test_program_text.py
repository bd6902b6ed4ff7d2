"""The program readers' text helpers against the plain forms they stand in for: keyword-anchored
matching against ``finditer``, the nesting-free split against the character walk."""

import re

import numpy as np
import pytest

from robocal.filtering.program import keyword_matches
from robocal.io.table import split_top

_MOVE = re.compile(r"\b(Move(?:L|J|C|AbsJ)?)\b([^;]*);", re.I)
_DECL = re.compile(r"\b(robtarget|jointtarget)\s+(\w+)\s*:=\s*", re.I)
_WORDS = ("MoveL", "movej", "MOVEC", "MoveAbsJ", "Move", "xMoveL", "MoveLx", "robtarget", "ROBTARGET",
          "jointtarget", "p1", ":=", ";", " ", "\n", ",", "MoveL MoveJ", "robtarget robtarget", "_MoveL")


def _spans(matches):
    return [(m.start(), m.end(), m.groups()) for m in matches]


@pytest.mark.parametrize("seed", range(40))
def test_keyword_matches_are_finditer_s(seed):
    rng = np.random.default_rng(seed)
    text = "".join(rng.choice(_WORDS, 60))
    for pattern, words in ((_MOVE, ("move",)), (_DECL, ("robtarget", "jointtarget"))):
        assert _spans(keyword_matches(pattern, text, words)) == _spans(pattern.finditer(text))


def test_a_match_holding_the_next_keyword_hides_it_as_finditer_does():
    text = "MoveL MoveJ p1; MoveL p2;"
    assert _spans(keyword_matches(_MOVE, text, ("move",))) == _spans(_MOVE.finditer(text))
    assert len(list(keyword_matches(_MOVE, text, ("move",)))) == 2


def test_code_that_is_not_ascii_scans_as_usual():
    # 'ſ' and 'ı' fold onto s and i under re.I, and str.lower leaves them: only a full scan finds them
    text = "CONST jointtarget j:=[[0]]; CONST joıntTarget k:=[[0]]; Moveſ"
    pattern = re.compile(r"\b(joint)target\s+(\w+)", re.I)
    expected = _spans(pattern.finditer(text))
    assert len(expected) == 2
    assert _spans(keyword_matches(pattern, text, ("jointtarget",))) == expected


@pytest.mark.parametrize("text", ["a,b,c", "", ",", "a,,b", " p0, v500 ,z10,gun ", "f(a,b),c", "a),b,c", "[1,2],{3,4}",
                                  "a,'x,y',b"])
def test_split_top_plain_and_walked_agree(text):
    walked = _walk(text)
    assert split_top(text) == walked


def _walk(text):
    parts, depth, last = [], 0, 0
    for i, c in enumerate(text):
        depth += c in "([{"
        depth -= c in ")]}"
        if c == "," and depth == 0:
            parts.append(text[last:i])
            last = i + 1
    return parts + [text[last:]]


_MODULE = """MODULE Cell
  PERS tooldata gun:=[TRUE,[[0,0,150],[1,0,0,0]],[2,[0,0,50],[1,0,0,0],0,0,0]];
  PERS wobjdata table:=[FALSE,TRUE,"",[[500,0,200],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
  CONST robtarget p1:=[[400,0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST jointtarget j1:=[ [10,20,-15,30,45,-40],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR robtarget p2:= [ [ 410.5 , 5, 480 ], [0,0,1,0], [-1,0,-1,0], [9E9,9E9,9E9,9E9,9E9,9E9] ];
  PROC main()
    MoveL p1,v500,z10,gun;
    MoveAbsJ j1,v500,fine,gun\\WObj:=table;
    MoveAbsJ [[0,10,20,0,30,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v500,fine,gun;
    movel [[420,0,470],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v500,z10,gun;
    MoveJ Offs(p2,0,0,50),v500,z10,gun;
    ! MoveL p9,v500,z10,gun;
  ENDPROC
ENDMODULE
"""


def test_rapid_reads_the_same_targets_as_with_plain_scans(tmp_path, monkeypatch):
    from robocal.filtering import rapid

    path = tmp_path / "cell.mod"
    path.write_text(_MODULE)

    def summary(program):
        return [(t.name, t.line, t.kind, t.fields, None if t.position is None else t.position.tolist(),
                 None if t.rotation is None else t.rotation.tolist(), None if t.q is None else t.q.tolist(),
                 t.config, t.tool, t.user, t.unsupported, [o.text for o in t.offsets]) for t in program.targets]

    fast = summary(rapid.read(path))
    monkeypatch.setattr(rapid, "keyword_matches", lambda pattern, code, words: pattern.finditer(code))
    monkeypatch.setattr(rapid, "matches_at", lambda pattern, code, starts: pattern.finditer(code))
    plain = summary(rapid.read(path))
    assert fast == plain
    kinds = [(row[0], row[2]) for row in fast]
    assert ("p1", "pose") in kinds and ("j1", "joints") in kinds and ("p2", "pose") in kinds
    assert sum(name.startswith("line") for name, _ in kinds) == 2  # the two inline targets


def _krl_summary(program):
    return [(t.name, t.line, t.kind, {k: f.text for k, f in t.fields.items()},
             None if t.position is None else t.position.tolist(), None if t.rotation is None else t.rotation.tolist(),
             None if t.q is None else t.q.tolist(), {k: v for k, v in t.config.items() if k != "_key"}, t.tool, t.user,
             t.unsupported) for t in program.targets], sorted(program.tools), sorted(program.users)


_SRC = """DEF cell()
  BAS(#INITMOV, 0)
  $BASE = {FRAME: X 100,Y 0,Z 10,A 0,B 0,C 0}
  $TOOL = TOOL_DATA[2]
  bas (#base, 1)
  PTP XP1 ; taught
  lin {X 400,Y 10,Z 500,A 0,B 90,C 0,S 2,T 10} C_DIS
  FDAT_ACT = FP1
  CIRC XP2, XP3
  SPTP XJ1 WITH $TOOL = STOOL2(FP1), $BASE = SBASE(FP1.BASE_NO)
  SLIN XP4
  DECL E6POS local={X 410,Y 0,Z 480,A 10,B 80,C 5,S 6,T 0}
  PTP local
  PTP_REL {A1 5}
  Ptp XP5 C_PTP
END
"""

_DAT = """DEFDAT cell
  DECL FDAT FP1={TOOL_NO 3,BASE_NO 4,IPO_FRAME #BASE}
  DECL E6POS XP1={X 400,Y 0,Z 500,A 0,B 90,C 0,S 2,T 10,E1 0.0}
  DECL E6POS XP2={X 420,Y 20,Z 500,A 0,B 90,C 0,S 'B010',T 'B1010'}
  DECL POS XP3={X 440,Y 0,Z 500,A 0,B 90,C 0,S 2,T 10}
  DECL E6POS XP4={X 400,Y -20,Z 520,A -5.5,B 85,C 1.25,S 2,T 10}
  DECL E6POS XP5={X 380,Y 0,Z 540,A 0,B 90,C 0}
  DECL E6AXIS XJ1={A1 10,A2 -80,A3 90,A4 0,A5 30,A6 0}
  DECL FRAME F1={X 1,Y 2,Z 3,A 0,B 0,C 0}
ENDDAT
"""


def test_krl_reads_the_same_where_its_lines_are_not_ascii(tmp_path):
    """The ASCII fast paths (a pattern run only where its words stand, declarations found by their
    keyword) read what the patterns alone read: every line's code given a trailing no-break space
    (not ASCII, and space to the patterns) takes the patterns' own path."""
    from robocal.filtering import krl

    def written(folder, mark):
        folder.mkdir()
        for name, text in (("cell.src", _SRC), ("cell.dat", _DAT)):
            lines = [line.split(";", 1) for line in text.splitlines()]
            body = "\n".join(parts[0] + mark + (";" + parts[1] if len(parts) > 1 else "") for parts in lines)
            (folder / name).write_text(body + "\n", encoding="utf-8")
        return krl.read(folder / "cell.src")

    fast, plain = _krl_summary(written(tmp_path / "a", "")), _krl_summary(written(tmp_path / "b", "\u00a0"))
    assert fast == plain
    names = [row[0] for row in fast[0]]
    assert {"XP1", "XP2", "XP3", "XP4", "XP5", "XJ1", "LOCAL"} <= {n.upper() for n in names}
    assert any(n.startswith("line") for n in names)  # the inline LIN target


def test_rotations_turned_together_are_each_targets_own():
    """turn_by_angles (every pose target of a program in one call) against rpy_to_matrix of each target's
    own three numbers, as KRL and FANUC read them one at a time before: the same bits."""
    from robocal.filtering.program import Field, Target, turn_by_angles
    from robocal.math.so3 import rpy_to_matrix

    rng = np.random.default_rng(3)
    angles = rng.uniform(-180.0, 180.0, (300, 3)).round(4)
    targets = [Target(f"p{i}", i, "pose", {k: Field(0, 1, f"{v:.4f}") for k, v in zip("WPR", a)})
               for i, a in enumerate(angles)]
    targets.append(Target("j", 999, "joints", {"J1": Field(0, 1, "10")}, q=np.zeros(6)))
    targets.append(Target("r", 1000, "pose", {}, unsupported="a register"))
    turn_by_angles(targets, ("W", "P", "R"))
    for t, a in zip(targets, angles):
        assert np.array_equal(t.rotation, rpy_to_matrix(np.radians([float(f"{v:.4f}") for v in a])))
    assert targets[-2].rotation is None and targets[-1].rotation is None


def test_angle_decimals_made_together_are_each_targets_own():
    """The decimals a target's angles keep (the file's own where they carry the correction), decided for
    many targets at once, against the decision on each target's own matrices, as it was made one target
    at a time: files written with 0 to 4 decimals, corrections that do and do not show at them."""
    import math

    from robocal.filtering.language import ANGLE_KEEP_DEG, DECIMALS, angle_decimals_many
    from robocal.filtering.program import Field
    from robocal.math.so3 import rpy_to_matrix

    def one(fields, values):
        own = min(f.decimals() for f in fields)
        if own >= DECIMALS["deg"]:
            return DECIMALS["deg"]
        R = rpy_to_matrix(np.radians(np.asarray(values, float)))
        Q = rpy_to_matrix(np.radians(np.round(np.asarray(values, float), own)))
        turned = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(R @ Q.T) - 1.0) / 2.0))))
        return own if turned <= ANGLE_KEEP_DEG else DECIMALS["deg"]

    rng = np.random.default_rng(5)
    fields, values = [], []
    for _ in range(2000):
        d = int(rng.integers(0, 5))
        written = rng.uniform(-180.0, 180.0, 3).round(d)
        fields.append([Field(0, 1, f"{v:.{d}f}") for v in written])
        values.append(tuple(written + rng.normal(size=3) * 10.0 ** -(d + 1) * rng.choice([0.1, 3.0])))
    decided = angle_decimals_many(fields, values)
    assert decided == [one(f, v) for f, v in zip(fields, values)]
    assert len(set(decided)) >= 3  # both outcomes, several decimals


_UR_WORDS = ("x", "wp", "wp1", "p", "q_near", " ", "[", "]", "[0]", "=", "==", " = ", "(", ")", ",", "1", "\n",
             "p[0.1, 0.2, 0.3, 0, 0, 0]", "x[1] = 2", "a[b[0]=1", "pose_trans(", "movel(")


@pytest.mark.parametrize("seed", range(30))
def test_urscript_subscripted_names_and_call_arguments_are_the_per_name_searches_and_the_walk(seed):
    """One pass for the variables changed element by element against a search per name (each name,
    at a word's start, followed by [...] =), and the bracket scan of a call's arguments against the
    character walk it replaced, closed calls and unclosed ones, on random URScript-like text."""
    import re

    from robocal.filtering import urscript

    rng = np.random.default_rng(seed)
    code = "".join(rng.choice(_UR_WORDS, 120))
    names = set(re.findall(r"[A-Za-z_]\w*", code))
    per_name = {n for n in names if re.search(r"\b" + re.escape(n) + r"\s*\[[^\]]*\]\s*=(?!=)", code)}
    assert set(urscript._SUBSCRIPTED.findall(code)) == per_name

    def walked(code, open_paren):
        depth, i = 1, open_paren + 1
        while i < len(code) and depth:
            depth += {"(": 1, "[": 1, ")": -1, "]": -1}.get(code[i], 0)
            i += 1
        return code[open_paren + 1:i - 1]

    for at in [i for i, c in enumerate(code) if c == "("]:
        args, starts = urscript._call_arguments(code, at)
        body = walked(code, at)
        assert ",".join(args) == ",".join(p.strip() for p in split_top(body))
        assert all(code[s:s + len(a)] == a for a, s in zip(args, starts) if a)


def test_rotation_vectors_made_together_are_each_targets_own():
    """URScript's written rotation vectors, converted for all targets at once, against each target converted
    alone, as write made them one at a time: rotations near a half turn included, where the nearer of the
    two spellings flips."""
    import math

    from scipy.spatial.transform import Rotation

    from robocal.filtering.language import rotation_vectors
    from robocal.filtering.program import Field, Target

    rng = np.random.default_rng(6)
    R = Rotation.random(1500, random_state=rng).as_matrix()
    R[:200] = Rotation.from_rotvec(rng.normal(size=(200, 3)) * 0.01 + np.array([math.pi - 1e-3, 0.0, 0.0])).as_matrix()
    written = rng.normal(size=(1500, 3)) * 2.0
    keys = ("rx", "ry", "rz")
    targets = [Target(f"w{i}", i, "pose", {k: Field(0, 1, f"{v:.6f}") for k, v in zip(keys, w)})
               for i, w in enumerate(written)]
    poses = [np.block([[M, np.zeros((3, 1))], [np.zeros((1, 3)), np.ones((1, 1))]]) for M in R]
    together = rotation_vectors(list(zip(targets, poses)), keys)
    alone = [rotation_vectors([(t, pose)], keys)[0] for t, pose in zip(targets, poses)]
    assert all(np.array_equal(a, b) for a, b in zip(together, alone))
    flipped = sum(np.linalg.norm(r) > math.pi for r in together)
    assert 0 < flipped < len(together)  # both spellings taken
    for r, M in zip(together, R):
        np.testing.assert_allclose(Rotation.from_rotvec(r).as_matrix(), M, atol=1e-9)
