"""An independent robot controller for the filtering tests: it shares no code with robocal.

It writes programs whose targets were taught at known joints (KUKA KRL with its .dat and
$config.dat, ABB RAPID, URScript, FANUC .ls), in each language's documented form, with the
configuration data computed from the joints as the manuals define them (shared/CONTROLLERS.md:
KUKA's S and T, ABB's cf1 cf4 cf6 cfx, FANUC's F/N U/D T/B and turns); it reads a filtered
program's numbers back with its own patterns; and its inverse kinematics (tests/independent.py)
starts from the taught joints, as a controller moving to a target does.

Geometric facts are taken in the robot's "A1 system": its world frame without the pedestal,
turned by joint 1 (x forward, z up), for arms whose arm plane holds axes 2 and 3.
"""

from __future__ import annotations

import functools
import math
import re

import independent as ind
import numpy as np
from scipy.spatial.transform import Rotation

NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def frame(xyz, rpy_deg) -> np.ndarray:
    """x, y, z mm and fixed-axis angles (deg): R = Rz(c)·Ry(b)·Rx(a)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", rpy_deg, degrees=True).as_matrix()
    T[:3, 3] = xyz
    return T


def fixed_angles(R) -> np.ndarray:
    """(a, b, c) deg with R = Rz(c)·Ry(b)·Rx(a)."""
    return Rotation.from_matrix(R).as_euler("xyz", degrees=True)


def a1_system(name: str, g, q, pedestal, axis1_sign: float):
    """Wrist centre, elbow (axis 3) and shoulder (axis 2) points in the A1 system (mm)."""
    B = pedestal @ ind.base_of(name)
    frames = [B @ F for F in ind.link_frames(g, q)]
    wc = frames[3][:3, 3]  # the wrist centre: origin after joint 4 (a4 = d5 = a5 = 0)
    shoulder, elbow = (B @ ind.link_frames(g, q)[0])[:3, 3], frames[1][:3, 3]
    back = np.linalg.inv(pedestal)
    turn = Rotation.from_euler("z", -axis1_sign * q[0]).as_matrix()

    def local(p):
        return turn @ (back[:3, :3] @ p + back[:3, 3])

    return local(wc), local(elbow), local(shoulder)


# --- KUKA ---------------------------------------------------------------------------------------

def kuka_status(name, g, q, pedestal=np.eye(4)) -> tuple[int, int]:
    """S and T of joints q (rad) of a KUKA-convention arm (A1 about −Z)."""
    wc, _, _ = a1_system(name, g, q, pedestal, axis1_sign=-1.0)
    bit0 = int(wc[0] < 0)  # overhead: the wrist point behind axis 1 in the A1 system
    phi = _stretched_a3(name, tuple(map(tuple, (g[k] for k in ("a", "alpha", "theta", "d", "beta")))))
    bit1 = int(q[2] >= phi)  # A3 at or beyond the angle where the forearm is stretched
    bit2 = int(q[4] <= 0)
    return bit0 | bit1 << 1 | bit2 << 2, sum(1 << i for i in range(6) if q[i] < 0)


@functools.lru_cache(maxsize=16)
def _stretched_a3(name, table) -> float:
    """The A3 at which the wrist point is furthest from axis 2 (the forearm stretched)."""
    g = {k: np.array(v) for k, v in zip(("a", "alpha", "theta", "d", "beta"), table)}
    grid = np.radians(np.linspace(-180, 180, 721))

    def reach(a3):
        q = np.array([0.0, 0.0, a3, 0.0, 0.0, 0.0])
        F = ind.link_frames(g, q)
        return np.linalg.norm(F[3][:3, 3] - F[0][:3, 3])

    best = grid[np.argmax([reach(a) for a in grid])]
    fine = np.linspace(best - 0.01, best + 0.01, 401)
    return float(fine[np.argmax([reach(a) for a in fine])])


# --- ABB ----------------------------------------------------------------------------------------

def abb_config(name, g, q, pedestal=np.eye(4)) -> list[int]:
    wc, elbow, shoulder = a1_system(name, g, q, pedestal, axis1_sign=1.0)
    lower, w = elbow - shoulder, wc - shoulder
    behind_axis1 = int(wc[0] < 0)
    behind_lower = int(lower[2] * w[0] - lower[0] * w[2] < 0)
    cf = [int(math.floor(math.degrees(q[j]) / 90.0)) for j in (0, 3, 5)]
    return cf + [behind_axis1 << 2 | behind_lower << 1 | int(q[4] < 0)]


# --- FANUC --------------------------------------------------------------------------------------

def fanuc_config(name, g, q, pedestal=np.eye(4)) -> str:
    """The CONFIG string of the model's joints q (rad)."""
    wc, elbow, shoulder = a1_system(name, g, q, pedestal, axis1_sign=1.0)
    w, e = wc - shoulder, elbow - shoulder
    up = w[0] * e[2] - w[2] * e[0] > 0
    turns = [math.ceil((math.degrees(q[j]) - 180.0) / 360.0) for j in (0, 3, 5)]
    return f"{'F' if q[4] > 0 else 'N'} {'U' if up else 'D'} {'T' if wc[0] > 0 else 'B'}, " + \
        ", ".join(str(t) for t in turns)


# --- programs -----------------------------------------------------------------------------------

def krl_program(poses, joints, s_t, tool_no=2, base_no=1) -> tuple[str, str]:
    """A .src and .dat: E6POS XPi (mm, deg, S, T) reached by PTP/LIN with FDAT tool and base,
    E6AXIS XJi by PTP."""
    src = ["&ACCESS RVP", "DEF cell()", "  BAS(#INITMOV, 0)"]
    dat = ["DEFDAT cell", f"  DECL FDAT FP0={{TOOL_NO {tool_no},BASE_NO {base_no},IPO_FRAME #BASE,POINT2[] \" \"}}"]
    for i, (T, (s, t)) in enumerate(zip(poses, s_t)):
        c, b, a = fixed_angles(T[:3, :3])
        src += ["  FDAT_ACT = FP0", "  BAS(#PTP_PARAMS, 100)", f"  {'PTP' if i % 2 else 'LIN'} XP{i + 1} ; taught"]
        dat.append(f"  DECL E6POS XP{i + 1}={{X {T[0, 3]:.3f},Y {T[1, 3]:.3f},Z {T[2, 3]:.3f},A {a:.4f},B {b:.4f},"
                   f"C {c:.4f},S {s},T {t},E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}}")
    for i, q in enumerate(joints):
        v = np.degrees(q)
        src += ["  FDAT_ACT = FP0", f"  PTP XJ{i + 1}"]
        dat.append(f"  DECL E6AXIS XJ{i + 1}={{A1 {v[0]:.4f},A2 {v[1]:.4f},A3 {v[2]:.4f},A4 {v[3]:.4f},"
                   f"A5 {v[4]:.4f},A6 {v[5]:.4f},E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}}")
    return "\r\n".join(src + ["END", ""]), "\r\n".join(dat + ["ENDDAT", ""])


def krl_config(tools: dict[int, np.ndarray], bases: dict[int, np.ndarray]) -> str:
    lines = ["DEFDAT $CONFIG", ";FOLD BASE/TOOL DATA"]
    for kind, table in (("TOOL", tools), ("BASE", bases)):
        for n, T in table.items():
            c, b, a = fixed_angles(T[:3, :3])
            lines.append(f"{kind}_DATA[{n}]={{X {T[0, 3]:.4f},Y {T[1, 3]:.4f},Z {T[2, 3]:.4f},A {a:.5f},B {b:.5f},"
                         f"C {c:.5f}}}")
    return "\n".join(lines + [";ENDFOLD", "ENDDAT", ""])


def read_krl(dat: str) -> dict[str, dict[str, float]]:
    out = {}
    for m in re.finditer(r"DECL (?:E6POS|E6AXIS) (\w+)=\{([^}]*)\}", dat):
        out[m.group(1)] = {k.upper(): float(v) for k, v in re.findall(r"(\w+) (" + NUM + r")", m.group(2))}
    return out


def rapid_program(poses, cfs, joints, tool: np.ndarray, wobj: np.ndarray) -> str:
    def quat(R):
        x, y, z, w = Rotation.from_matrix(R).as_quat()
        return f"{w:.8f},{x:.8f},{y:.8f},{z:.8f}"

    lines = ["MODULE Cell", f"  PERS tooldata gun:=[TRUE,[[{tool[0, 3]:.3f},{tool[1, 3]:.3f},{tool[2, 3]:.3f}],"
             f"[{quat(tool[:3, :3])}]],[2,[0,0,50],[1,0,0,0],0,0,0]];",
             f"  TASK PERS wobjdata table:=[FALSE,TRUE,\"\",[[{wobj[0, 3]:.3f},{wobj[1, 3]:.3f},{wobj[2, 3]:.3f}],"
             f"[{quat(wobj[:3, :3])}]],[[0,0,0],[1,0,0,0]]];"]
    for i, (T, cf) in enumerate(zip(poses, cfs)):
        lines.append(f"  CONST robtarget p{i + 1}:=[[{T[0, 3]:.3f},{T[1, 3]:.3f},{T[2, 3]:.3f}],[{quat(T[:3, :3])}],"
                     f"[{cf[0]},{cf[1]},{cf[2]},{cf[3]}],[9E9,9E9,9E9,9E9,9E9,9E9]];")
    for i, q in enumerate(joints):
        v = np.degrees(q)
        lines.append(f"  CONST jointtarget j{i + 1}:=[[{','.join(f'{x:.4f}' for x in v)}],[9E9,9E9,9E9,9E9,9E9,9E9]];")
    lines += ["  PROC main()", "    ConfJ \\On;", "    ConfL \\On;"]
    lines += [f"    MoveJ p{i + 1},v500,fine,gun\\WObj:=table;" for i in range(len(poses))]
    lines += [f"    MoveAbsJ j{i + 1},v500,fine,gun\\WObj:=table;" for i in range(len(joints))]
    return "\n".join(lines + ["  ENDPROC", "ENDMODULE", ""])


def read_rapid(text: str) -> dict[str, list[float]]:
    out = {}
    for m in re.finditer(r"(robtarget|jointtarget) (\w+):=(\[.*?\]);", text):
        out[m.group(2)] = [float(v) for v in re.findall(NUM, m.group(3))]
    return out


def fanuc_program(poses, configs, joints, uf=1, ut=2) -> str:
    lines = ["/PROG  CELL", "/ATTR", "/MN"]
    k = 0
    for i in range(len(poses)):
        k += 1
        lines.append(f"{k:4d}:{'J' if i % 2 else 'L'} P[{i + 1}] {'100%' if i % 2 else '500mm/sec'} FINE    ;")
    for i in range(len(joints)):
        k += 1
        lines.append(f"{k:4d}:J P[{len(poses) + i + 1}] 100% FINE    ;")
    lines += [f"{k + 1:4d}:J PR[3] 100% FINE    ;", f"{k + 2:4d}:L P[1] 500mm/sec FINE Offset,PR[4]    ;", "/POS"]
    for i, (T, cfg) in enumerate(zip(poses, configs)):
        w, p, r = fixed_angles(T[:3, :3])
        lines += [f"P[{i + 1}]{{", "   GP1:", f"\tUF : {uf}, UT : {ut},\t\tCONFIG : '{cfg}',",
                  f"\tX = {T[0, 3]:9.3f}  mm,\tY = {T[1, 3]:9.3f}  mm,\tZ = {T[2, 3]:9.3f}  mm,",
                  f"\tW = {w:9.3f} deg,\tP = {p:9.3f} deg,\tR = {r:9.3f} deg", "};"]
    for i, J in enumerate(joints):
        v = np.degrees(J)
        lines += [f"P[{len(poses) + i + 1}]{{", "   GP1:", f"\tUF : {uf}, UT : {ut},",
                  f"\tJ1= {v[0]:9.3f} deg,\tJ2= {v[1]:9.3f} deg,\tJ3= {v[2]:9.3f} deg,",
                  f"\tJ4= {v[3]:9.3f} deg,\tJ5= {v[4]:9.3f} deg,\tJ6= {v[5]:9.3f} deg", "};"]
    return "\r\n".join(lines + ["/END", ""])


def read_fanuc(text: str) -> dict[int, dict]:
    out = {}
    for m in re.finditer(r"P\[(\d+)\]\{(.*?)\};", text, re.S):
        body = m.group(2)
        cfg = re.search(r"CONFIG : '([^']*)'", body)
        values = {k: float(v) for k, v in re.findall(r"\b(X|Y|Z|W|P|R|J\d)\s*=\s*(" + NUM + ")", body)}
        out[int(m.group(1))] = {"config": None if cfg is None else cfg.group(1), **values}
    return out
