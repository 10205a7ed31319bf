"""Rewrite bundled CMU clips into rigs the naming conventions of `tests.conventions` do not cover.

Structure, not only names: twist/bend split bones (Daz Genesis 8), leaf twist bones and a root
joint under the pelvis's travel (Unreal's mannequin), joints above the hips (a Blender armature:
`Armature -> Root -> Hips`, the travel on `Root`), legs without toe joints, bones along local Y
and rigs whose joint frames hold large constant rest rotations. Every rewrite keeps the world
position of every CMU joint (the inserted joints sit on the bones), so a rig's results can be
compared with the CMU clip's; `RIGS[name].joint` maps a CMU joint name to the rig's.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial.transform import Rotation

from fourierjax.io.bvh import Motion
from fourierjax.skeleton import Topology
from tests.conventions import _local_pose, reframe

_ROT = ("Zrotation", "Yrotation", "Xrotation")
_SIX = ("Xposition", "Yposition", "Zposition", *_ROT)


@dataclasses.dataclass
class _Rig:
    """An editable skeleton with its per-frame local pose (float64): rotations `R [F, J, 3, 3]` and
    translations `T [F, J, 3]` (the offset where a joint has no position channels)."""

    names: list[str]
    parents: list[int]
    channels: list[tuple[str, ...]]
    R: np.ndarray
    T: np.ndarray
    ends: list[tuple[int, np.ndarray]]  # (parent joint, offset)
    frame_time_s: float

    @classmethod
    def of(cls, motion: Motion) -> _Rig:
        t = motion.topology
        R, T = _local_pose(motion)
        ends = [(p, np.array(o, float)) for p, o in zip(t.end_site_parents, motion.end_site_offsets)]
        return cls(list(t.names), list(t.parents), list(t.channels), R, T, ends, motion.frame_time_s)

    def index(self, name: str) -> int:
        return self.names.index(name)

    def add(self, name: str, parent: int, T: np.ndarray, R: np.ndarray | None = None, channels=_ROT) -> int:
        self.names.append(name)
        self.parents.append(parent)
        self.channels.append(tuple(channels))
        F = len(self.T)
        R = np.broadcast_to(np.eye(3), (F, 3, 3)) if R is None else R
        self.R = np.concatenate([self.R, R[:, None]], axis=1)
        self.T = np.concatenate([self.T, np.broadcast_to(T, (F, 3))[:, None]], axis=1)
        return len(self.names) - 1

    def split_bone(self, joint: str, child: str, name: str, fraction: float, *, twist: bool) -> int:
        """A joint inserted on the bone from `joint` to `child`, `fraction` of the way along.

        With `twist`, `joint`'s rotation is split into swing then twist about the bone
        (`R = R_swing R_twist`, exact): `joint` keeps the swing, the new joint takes the twist and
        all of `joint`'s children and End Sites (Daz's `lThighBend -> lThighTwist`). Without, the
        new joint holds the identity and only `child` moves under it."""
        j, c = self.index(joint), self.index(child)
        bone = self.T[0, c].copy()
        at = fraction * bone
        if twist:
            axis = bone / np.linalg.norm(bone)
            q = Rotation.from_matrix(self.R[:, j]).as_quat()  # xyzw
            proj = (q[:, :3] @ axis)[:, None] * axis
            q_twist = np.concatenate([proj, q[:, 3:]], axis=1)
            q_twist /= np.linalg.norm(q_twist, axis=1, keepdims=True)
            R_twist = Rotation.from_quat(q_twist).as_matrix()
            self.R[:, j] = np.einsum("fij,fkj->fik", self.R[:, j], R_twist)  # R R_twist^T: the swing
            n = self.add(name, j, at, R_twist)
            moved = [k for k, p in enumerate(self.parents) if p == j and k != n]
            self.ends = [(n, o - at) if p == j else (p, o) for p, o in self.ends]
        else:
            n = self.add(name, j, at)
            moved = [c]
        for k in moved:
            self.parents[k] = n
            self.T[:, k] -= at
        return n

    def insert_above(self, joint: str, name: str, children: list[str]) -> int:
        """A joint at `joint`'s origin, holding the identity, that `children` hang from (Daz's
        `hip -> pelvis -> thighs`)."""
        n = self.add(name, self.index(joint), np.zeros(3))
        for c in children:
            self.parents[self.index(c)] = n
        return n

    def remove(self, name: str) -> None:
        """Drop a joint whose rotation is the identity on every frame (children keep their place)."""
        j = self.index(name)
        assert np.allclose(self.R[:, j], np.eye(3), atol=1e-12), f"{name} rotates"
        for k, p in enumerate(self.parents):
            if p == j:
                self.parents[k] = self.parents[j]
                self.T[:, k] += self.T[:, j]
        self.ends = [(self.parents[j], o + self.T[0, j]) if p == j else (p, o) for p, o in self.ends]
        self._drop(j)

    def drop_leaf(self, name: str, *, end_site: bool = True) -> None:
        """Drop a leaf joint and its End Sites; with `end_site` its parent gets an End Site where the
        joint was (a foot without toe joints ends at the ball)."""
        j = self.index(name)
        assert j not in self.parents, f"{name} has children"
        self.ends = [(p, o) for p, o in self.ends if p != j]
        if end_site:
            self.ends.append((self.parents[j], self.T[0, j].copy()))
        self._drop(j)

    def _drop(self, j: int) -> None:
        keep = [k for k in range(len(self.names)) if k != j]
        new = {k: i for i, k in enumerate(keep)}
        self.parents = [new.get(self.parents[k], -1) if self.parents[k] >= 0 else -1 for k in keep]
        self.names = [self.names[k] for k in keep]
        self.channels = [self.channels[k] for k in keep]
        self.R, self.T = self.R[:, keep], self.T[:, keep]
        self.ends = [(new[p], o) for p, o in self.ends]

    def new_root(self, name: str, channels=_SIX, *, travel: bool = False) -> int:
        """A joint above the current root. With `travel` it takes the root's horizontal (x, z)
        translation, which the old root then no longer has (Unreal's `root`, Blender's `Root`)."""
        old = self.parents.index(-1)
        T = np.zeros_like(self.T[:, old])
        if travel:
            T[:, [0, 2]] = self.T[:, old][:, [0, 2]]
            self.T[:, old, 0] = 0.0
            self.T[:, old, 2] = 0.0
        n = self.add(name, -1, T, channels=channels)
        self.parents[old] = n
        return n

    def motion(self, names: dict[str, str] | None = None) -> Motion:
        """The rig as a Motion, joints in depth-first order, renamed by `names` (others keep theirs)."""
        order: list[int] = []

        def visit(j):
            order.append(j)
            for k in range(len(self.names)):
                if self.parents[k] == j:
                    visit(k)

        for r in [k for k, p in enumerate(self.parents) if p < 0]:
            visit(r)
        pos = {j: i for i, j in enumerate(order)}
        F = len(self.T)
        cols = []
        for j in order:
            chans = self.channels[j]
            rot = [c[0] for c in chans if c.endswith("rotation")]
            euler = Rotation.from_matrix(self.R[:, j]).as_euler("".join(rot), degrees=True) if rot else None
            for c in chans:
                cols.append(self.T[:, j, "XYZ".index(c[0])] if c.endswith("position")
                            else euler[:, rot.index(c[0])])
        channels = np.stack(cols, axis=1) if cols else np.zeros((F, 0))
        names = names or {}
        ends = sorted(((pos[p], o) for p, o in self.ends), key=lambda e: e[0])
        topo = Topology(tuple(names.get(self.names[j], self.names[j]) for j in order),
                        tuple(pos[self.parents[j]] if self.parents[j] >= 0 else -1 for j in order),
                        tuple(self.channels[j] for j in order), tuple(p for p, _ in ends))
        # (Position channels replace a joint's offset; the offset is the first frame's.)
        offsets = np.array([np.zeros(3) if self.parents[j] < 0 else self.T[0, j] for j in order])
        return Motion(topo, offsets, np.array([o for _, o in ends]).reshape(-1, 3), channels, self.frame_time_s,
                      None)


def _names(central: dict[str, str], sided: dict[str, str]) -> dict[str, str]:
    out = dict(central)
    for side, (S, L, lo) in (("Left", ("Left", "L", "l")), ("Right", ("Right", "R", "r"))):
        for part, pattern in sided.items():
            out[side + part] = pattern.format(Left=S, L=L, l=lo)
    return out


def genesis8(motion: Motion) -> Motion:
    """Daz Genesis 8: `hip -> pelvis -> lThighBend -> lThighTwist -> lShin -> lFoot -> lMetatarsals
    -> lToe`, the spine `abdomenLower ... neckUpper -> head`, the arms `lCollar -> lShldrBend ->
    lShldrTwist -> lForearmBend -> lForearmTwist -> lHand`. The thigh's, the upper arm's and the
    forearm's rotations are split into bend and twist."""
    rig = _Rig.of(motion)
    for side, s in (("Left", "l"), ("Right", "r")):
        rig.remove(f"{side[0]}HipJoint")
        rig.split_bone(f"{side}UpLeg", f"{side}Leg", f"{s}ThighTwist", 0.35, twist=True)
        rig.split_bone(f"{side}Foot", f"{side}ToeBase", f"{s}Metatarsals", 0.5, twist=False)
        rig.split_bone(f"{side}Arm", f"{side}ForeArm", f"{s}ShldrTwist", 0.4, twist=True)
        rig.split_bone(f"{side}ForeArm", f"{side}Hand", f"{s}ForearmTwist", 0.4, twist=True)
    rig.insert_above("Hips", "pelvis", ["LeftUpLeg", "RightUpLeg"])
    names = _names(
        {"Hips": "hip", "LowerBack": "abdomenLower", "Spine": "abdomenUpper", "Spine1": "chestUpper",
         "Neck": "neckLower", "Neck1": "neckUpper", "Head": "head", "LeftFingerBase": "lCarpal1",
         "RightFingerBase": "rCarpal1", "LeftHandIndex1": "lIndex1", "RightHandIndex1": "rIndex1",
         "LThumb": "lThumb1", "RThumb": "rThumb1"},
        {"UpLeg": "{l}ThighBend", "Leg": "{l}Shin", "Foot": "{l}Foot", "ToeBase": "{l}Toe",
         "Shoulder": "{l}Collar", "Arm": "{l}ShldrBend", "ForeArm": "{l}ForearmBend", "Hand": "{l}Hand"})
    return rig.motion(names)


def unreal(motion: Motion) -> Motion:
    """Unreal's mannequin: `root` (on the floor, carrying the horizontal travel) -> `pelvis` ->
    `thigh_l -> calf_l -> foot_l -> ball_l`, leaf twist bones `thigh_twist_01_l` and
    `calf_twist_01_l` (and the arms' `upperarm_twist_01_l`, `lowerarm_twist_01_l`), `spine_01..03`,
    `neck_01`, `head`, `clavicle_l -> upperarm_l -> lowerarm_l -> hand_l`."""
    rig = _Rig.of(motion)
    for side, s in (("Left", "l"), ("Right", "r")):
        rig.remove(f"{side[0]}HipJoint")
        for bone, child, twist in (("UpLeg", "Leg", "thigh"), ("Leg", "Foot", "calf"),
                                   ("Arm", "ForeArm", "upperarm"), ("ForeArm", "Hand", "lowerarm")):
            j = rig.index(side + bone)
            rig.add(f"{twist}_twist_01_{s}", j, 0.5 * rig.T[0, rig.index(side + child)])
            rig.ends.append((len(rig.names) - 1, np.array([0.0, 0.5, 0.0])))
    rig.new_root("root", travel=True)
    names = _names(
        {"Hips": "pelvis", "LowerBack": "spine_01", "Spine": "spine_02", "Spine1": "spine_03", "Neck": "neck_01",
         "Neck1": "neck_02", "Head": "head", "LeftFingerBase": "index_metacarpal_l",
         "RightFingerBase": "index_metacarpal_r", "LeftHandIndex1": "index_01_l", "RightHandIndex1": "index_01_r",
         "LThumb": "thumb_01_l", "RThumb": "thumb_01_r"},
        {"UpLeg": "thigh_{l}", "Leg": "calf_{l}", "Foot": "foot_{l}", "ToeBase": "ball_{l}",
         "Shoulder": "clavicle_{l}", "Arm": "upperarm_{l}", "ForeArm": "lowerarm_{l}", "Hand": "hand_{l}"})
    return rig.motion(names)


def _along_y(motion: Motion) -> np.ndarray:
    """Per-joint frames whose local Y points to the first child (Blender and Mixamo bones), no roll."""
    t = motion.topology
    out = []
    for j in range(t.num_joints):
        kids = [c for c in t.children(j) if np.linalg.norm(motion.offsets[c]) > 1e-9]
        if kids:
            d = motion.offsets[kids[0]] / np.linalg.norm(motion.offsets[kids[0]])
            out.append(Rotation.align_vectors([d], [[0.0, 1.0, 0.0]])[0].as_matrix())
        else:
            out.append(np.eye(3))
    return np.array(out)


def blender(motion: Motion) -> Motion:
    """A Blender export of a Mixamo character: `Armature -> Root -> mixamorig:Hips`, the travel on
    `Root` (the hips keep their height), bones along local Y, 6 channels on every joint (Y up)."""
    rig = _Rig.of(motion)
    rig.new_root("Root", travel=True)
    rig.new_root("Armature")
    names = {n: "mixamorig:" + n for n in motion.topology.names}
    for side in ("Left", "Right"):
        names[f"{side}ToeBase"] = f"mixamorig:{side}ToeBase"
    out = rig.motion(names)
    return reframe(out, _along_y(out), "XYZ")


def no_toes(motion: Motion) -> Motion:
    """The CMU rig without toe joints: each leg ends at its ankle (`LeftFoot`), whose End Site is
    where the toe joint was."""
    rig = _Rig.of(motion)
    for side in ("Left", "Right"):
        rig.drop_leaf(f"{side}ToeBase")
    return rig.motion({"Hips": "Hips"})


def rest_rotated(motion: Motion, seed: int = 3) -> Motion:
    """LAFAN-style names on joint frames turned by large random constant rotations (a rig whose rest
    pose, all channels zero, is far from any body pose, and whose channels hold large constant
    rotations), ZXY channels on every joint."""
    rng = np.random.default_rng(seed)
    J = motion.num_joints
    pre = Rotation.from_rotvec(rng.normal(size=(J, 3)) * 1.2).as_matrix()
    names = {n: n.replace("ToeBase", "Toe") for n in motion.topology.names}
    rig = _Rig.of(motion)
    return reframe(rig.motion(names), pre, "ZXY")


def composite(motion: Motion) -> Motion:
    """Everything at once: Daz Genesis 8 (bend/twist thighs and arms, `hip -> pelvis`), its toe
    joints dropped (the foot ends at `lMetatarsals`), Unreal-style leaf twist bones on the shins,
    `Armature -> Root -> hip` with the travel on `Root`, and large rest rotations with ZXY channels
    on every joint."""
    g = _Rig.of(genesis8(motion))
    for s in ("l", "r"):
        g.drop_leaf(f"{s}Toe")
        j = g.index(f"{s}Shin")
        g.add(f"{s}ShinTwist_leaf", j, 0.5 * g.T[0, g.index(f"{s}Foot")])
        g.ends.append((len(g.names) - 1, np.array([0.0, 0.4, 0.0])))
    g.new_root("Root", travel=True)
    g.new_root("Armature")
    out = g.motion()
    pre = Rotation.from_rotvec(np.random.default_rng(11).normal(size=(out.num_joints, 3))).as_matrix()
    return reframe(out, pre, "ZXY")


def no_knees(motion: Motion) -> Motion:
    """A rig that cannot be mapped: each leg is `LeftUpLeg -> LeftFoot -> LeftToeBase`, the knee
    joint removed (its rotation dropped: the leg is straight), names otherwise CMU's."""
    rig = _Rig.of(motion)
    for side in ("Left", "Right"):
        rig.R[:, rig.index(f"{side}Leg")] = np.eye(3)
        rig.remove(f"{side}Leg")
    return rig.motion()


def world(motion: Motion):
    """NumPy FK (float64): world joint positions `[F, J, 3]`, End Site positions `[F, E, 3]` and
    world joint orientations `[F, J, 4]` (wxyz)."""
    rig = _Rig.of(motion)
    F, J = rig.R.shape[:2]
    Rw, P = np.zeros((F, J, 3, 3)), np.zeros((F, J, 3))
    for j, p in enumerate(rig.parents):
        if p < 0:
            Rw[:, j], P[:, j] = rig.R[:, j], rig.T[:, j]
        else:
            Rw[:, j] = Rw[:, p] @ rig.R[:, j]
            P[:, j] = P[:, p] + np.einsum("fij,fj->fi", Rw[:, p], rig.T[:, j])
    ends = np.stack([P[:, p] + Rw[:, p] @ o for p, o in rig.ends], axis=1) if rig.ends else np.zeros((F, 0, 3))
    q = Rotation.from_matrix(Rw.reshape(-1, 3, 3)).as_quat().reshape(F, J, 4)
    return P, ends, np.concatenate([q[..., 3:], q[..., :3]], axis=-1)


def resample(motion: Motion, fps: float) -> Motion:
    """`motion` at `fps` frames per second over the same time span: joint rotations slerped and
    translations (position channels) linearly interpolated between the two nearest source frames;
    the same rig and channels. The last frame is at or before the source's last. A rate within
    0.1% of the source's (120 against a file's rounded 0.008333 s) keeps its frames."""
    from scipy.spatial.transform import Slerp

    rig = _Rig.of(motion)
    F = len(rig.T)
    dt = 1.0 / float(fps)
    if abs(dt - motion.frame_time_s) < 1e-3 * motion.frame_time_s:
        return motion
    t_src = np.arange(F) * motion.frame_time_s
    t = np.arange(int(np.floor(t_src[-1] / dt + 1e-9)) + 1) * dt
    t = np.minimum(t, t_src[-1])
    R = np.empty((len(t), len(rig.names), 3, 3))
    for j in range(len(rig.names)):
        R[:, j] = Slerp(t_src, Rotation.from_matrix(rig.R[:, j]))(t).as_matrix()
    T = np.stack([np.stack([np.interp(t, t_src, rig.T[:, j, a]) for a in range(3)], -1)
                  for j in range(len(rig.names))], 1)
    rig.R, rig.T, rig.frame_time_s = R, T, dt
    out = rig.motion()
    return dataclasses.replace(out, channels=_continue(out, motion), source=motion.source)


def _continue(out: Motion, ref: Motion) -> np.ndarray:
    """`out`'s rotation channels (degrees, from matrices: in [-180, 180]) shifted by whole turns
    to follow `ref`'s first frame and each other frame to frame, as a capture's are."""
    ch = out.channels.copy()
    rot = np.array([c.endswith("rotation") for chans in out.topology.channels for c in chans])
    d = np.diff(ch[:, rot], axis=0)
    ch[1:, rot] -= 360.0 * np.cumsum(np.round(d / 360.0), axis=0)
    ch[:, rot] += 360.0 * np.round((ref.channels[0, rot] - ch[0, rot]) / 360.0)
    return ch

#: name -> rewrite of a CMU clip
RIGS = {"genesis8": genesis8, "unreal": unreal, "blender": blender, "no_toes": no_toes,
        "rest_rotated": rest_rotated}

#: The legs each rig's body map must name: (hip, knee, ankle, toe) per side.
LEGS = {
    "genesis8": (("lThighBend", "lShin", "lFoot", "lToe"), ("rThighBend", "rShin", "rFoot", "rToe")),
    "unreal": (("thigh_l", "calf_l", "foot_l", "ball_l"), ("thigh_r", "calf_r", "foot_r", "ball_r")),
    "blender": (tuple(f"mixamorig:Left{p}" for p in ("UpLeg", "Leg", "Foot", "ToeBase")),
                tuple(f"mixamorig:Right{p}" for p in ("UpLeg", "Leg", "Foot", "ToeBase"))),
    "no_toes": (("LeftUpLeg", "LeftLeg", "LeftFoot", ""), ("RightUpLeg", "RightLeg", "RightFoot", "")),
    "rest_rotated": (("LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToe"),
                     ("RightUpLeg", "RightLeg", "RightFoot", "RightToe")),
    "composite": (("lThighBend", "lShin", "lFoot", "lMetatarsals"), ("rThighBend", "rShin", "rFoot", "rMetatarsals")),
}
#: (trajectory, pelvis) each rig's body map must name.
ROOTS = {"genesis8": ("hip", "hip"), "unreal": ("root", "pelvis"), "blender": ("Root", "mixamorig:Hips"),
         "no_toes": ("Hips", "Hips"), "rest_rotated": ("Hips", "Hips"), "composite": ("Root", "hip")}
