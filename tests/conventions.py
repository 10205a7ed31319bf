"""Rewrite bundled CMU clips into other rigs' conventions (names, channels, bone axes, up axis, units).

Each converter keeps the joint order, so joint `j` of a rewritten clip is joint `j` of the CMU
clip, and keeps world positions (up to the documented axis and unit change, undone by `undo`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial.transform import Rotation

from fourierjax.io.axes import from_y_up, up_rotation
from fourierjax.io.bvh import Motion
from fourierjax.skeleton import Topology

CMU_METRES_PER_UNIT = 0.0564

# CMU joint -> (side, part); joints not listed are extras (LHipJoint, Neck1, fingers, thumbs).
_CMU_PARTS = {
    "Hips": (None, "pelvis"), "LowerBack": (None, "spine0"), "Spine": (None, "spine1"),
    "Spine1": (None, "spine2"), "Neck": (None, "neck"), "Head": (None, "head"),
}
for _s, _S in (("left", "Left"), ("right", "Right")):
    _CMU_PARTS.update({
        f"{_S}UpLeg": (_s, "hip"), f"{_S}Leg": (_s, "knee"), f"{_S}Foot": (_s, "ankle"),
        f"{_S}ToeBase": (_s, "toe"), f"{_S}Shoulder": (_s, "collar"), f"{_S}Arm": (_s, "shoulder"),
        f"{_S}ForeArm": (_s, "elbow"), f"{_S}Hand": (_s, "wrist"),
    })

# convention -> (central part names, sided part -> name pattern with {L}/{Left}/{l}, extra name pattern)
_CONVENTIONS = {
    "mixamo": ({"pelvis": "mixamorig:Hips", "spine0": "mixamorig:Spine", "spine1": "mixamorig:Spine1",
                "spine2": "mixamorig:Spine2", "neck": "mixamorig:Neck", "head": "mixamorig:Head"},
               {"hip": "mixamorig:{Left}UpLeg", "knee": "mixamorig:{Left}Leg", "ankle": "mixamorig:{Left}Foot",
                "toe": "mixamorig:{Left}ToeBase", "collar": "mixamorig:{Left}Shoulder",
                "shoulder": "mixamorig:{Left}Arm", "elbow": "mixamorig:{Left}ForeArm",
                "wrist": "mixamorig:{Left}Hand"}, "mixamorig:Extra{i}"),
    "daz": ({"pelvis": "hip", "spine0": "abdomen", "spine1": "abdomen2", "spine2": "chest", "neck": "neck",
             "head": "head"},
            {"hip": "{l}Thigh", "knee": "{l}Shin", "ankle": "{l}Foot", "toe": "{l}Toe", "collar": "{l}Collar",
             "shoulder": "{l}Shldr", "elbow": "{l}ForeArm", "wrist": "{l}Hand"}, "extra{i}"),
    "max": ({"pelvis": "Pelvis", "spine0": "Waist", "spine1": "Spine", "spine2": "Chest", "neck": "Neck",
             "head": "Head"},
            {"hip": "{Left}Hip", "knee": "{Left}Knee", "ankle": "{Left}Ankle", "toe": "{Left}Toe",
             "collar": "{Left}Collar", "shoulder": "{Left}Shoulder", "elbow": "{Left}Elbow",
             "wrist": "{Left}Wrist"}, "Extra{i}"),
    "biped": ({"pelvis": "Bip01 Pelvis", "spine0": "Bip01 Spine", "spine1": "Bip01 Spine1",
               "spine2": "Bip01 Spine2", "neck": "Bip01 Neck", "head": "Bip01 Head"},
              {"hip": "Bip01 {L} Thigh", "knee": "Bip01 {L} Calf", "ankle": "Bip01 {L} Foot",
               "toe": "Bip01 {L} Toe0", "collar": "Bip01 {L} Clavicle", "shoulder": "Bip01 {L} UpperArm",
               "elbow": "Bip01 {L} Forearm", "wrist": "Bip01 {L} Hand"}, "Bip01 Extra{i}"),
    "smpl": ({"pelvis": "Pelvis", "spine0": "Spine1", "spine1": "Spine2", "spine2": "Spine3", "neck": "Neck",
              "head": "Head"},
             {"hip": "{L}_Hip", "knee": "{L}_Knee", "ankle": "{L}_Ankle", "toe": "{L}_Foot",
              "collar": "{L}_Collar", "shoulder": "{L}_Shoulder", "elbow": "{L}_Elbow", "wrist": "{L}_Wrist"},
             "Extra_{i}"),
    "lafan": ({"pelvis": "Hips", "spine0": "Spine", "spine1": "Spine1", "spine2": "Spine2", "neck": "Neck",
               "head": "Head"},
              {"hip": "{Left}UpLeg", "knee": "{Left}Leg", "ankle": "{Left}Foot", "toe": "{Left}Toe",
               "collar": "{Left}Shoulder", "shoulder": "{Left}Arm", "elbow": "{Left}ForeArm",
               "wrist": "{Left}Hand"}, "Extra{i}"),
    "bandai": ({"pelvis": "Hips", "spine0": "Spine", "spine1": "Chest", "spine2": "Chest2", "neck": "Neck",
                "head": "Head"},
               {"hip": "UpperLeg_{L}", "knee": "LowerLeg_{L}", "ankle": "Foot_{L}", "toe": "Toes_{L}",
                "collar": "Shoulder_{L}", "shoulder": "UpperArm_{L}", "elbow": "LowerArm_{L}",
                "wrist": "Hand_{L}"}, "joint_Extra{i}"),
}
#: Every convention `convert` knows; "zup" (Blender: Z up, 6 channels a joint), "metres" and
#: "scrambled" (names j0..jN) keep the CMU names or drop all of them.
CONVENTIONS = (*_CONVENTIONS, "zup", "metres", "scrambled")


def rename(motion: Motion, names) -> Motion:
    t = motion.topology
    return dataclasses.replace(motion, topology=Topology(tuple(names), t.parents, t.channels, t.end_site_parents))


def convention_names(topology: Topology, convention: str) -> tuple[str, ...]:
    """The CMU joint names of `topology` spelled in `convention`."""
    central, sided, extra = _CONVENTIONS[convention]
    out = []
    for i, n in enumerate(topology.names):
        side, part = _CMU_PARTS.get(n, (None, None))
        if part is None:
            out.append(extra.format(i=i))
        elif side is None:
            out.append(central[part])
        else:
            s = side == "left"
            out.append(sided[part].format(Left="Left" if s else "Right", L="L" if s else "R", l="l" if s else "r"))
    return tuple(out)


def _local_pose(motion: Motion):
    """Per-frame local rotation matrices `[F, J, 3, 3]` and translations `[F, J, 3]` (float64)."""
    t = motion.topology
    F = motion.num_frames
    R = np.broadcast_to(np.eye(3), (F, t.num_joints, 3, 3)).copy()
    T = np.broadcast_to(motion.offsets, (F, t.num_joints, 3)).copy()
    for j, chans in enumerate(t.channels):
        first = t.channel_offsets[j]
        rot = [k for k, c in enumerate(chans) if c.endswith("rotation")]
        for k, c in enumerate(chans):
            if c.endswith("position"):
                T[:, j, "XYZ".index(c[0])] = motion.channels[:, first + k]
        if rot:
            order = "".join(chans[k][0] for k in rot)
            R[:, j] = Rotation.from_euler(order, motion.channels[:, [first + k for k in rot]],
                                          degrees=True).as_matrix()
    return R, T


def reframe(motion: Motion, pre: np.ndarray, order: str) -> Motion:
    """Every joint with 6 channels (position, then rotation in `order`) and joint frames turned by
    the fixed `pre[j]` (`[J, 3, 3]`): world positions are unchanged."""
    t = motion.topology
    R, T = _local_pose(motion)
    parents = np.array(t.parents)
    Qp = np.where((parents >= 0)[:, None, None], pre[np.maximum(parents, 0)], np.eye(3))  # [J, 3, 3]
    R_new = np.einsum("jki,fjkl,jlm->fjim", Qp, R, pre)  # Q_p^T R_j Q_j
    T_new = np.einsum("jki,fjk->fji", Qp, T)
    offsets = np.einsum("jki,jk->ji", Qp, motion.offsets)
    ends = np.array([pre[p].T @ o for p, o in zip(t.end_site_parents, motion.end_site_offsets)]).reshape(-1, 3)
    F, J = motion.num_frames, t.num_joints
    euler = Rotation.from_matrix(R_new.reshape(-1, 3, 3)).as_euler(order, degrees=True).reshape(F, J, 3)
    channels = np.concatenate([T_new, euler], axis=-1).reshape(F, 6 * J)
    names = ("Xposition", "Yposition", "Zposition") + tuple(f"{a}rotation" for a in order)
    topo = Topology(t.names, t.parents, (names,) * J, t.end_site_parents)
    return Motion(topo, offsets, ends, channels, motion.frame_time_s, motion.source)


def _bone_along_x(motion: Motion) -> np.ndarray:
    """Per-joint pre-rotations turning each joint's local X towards its first child (Maya joint orients)."""
    t = motion.topology
    rng = np.random.default_rng(7)
    out = []
    for j in range(t.num_joints):
        roll = Rotation.from_rotvec([rng.uniform(-np.pi, np.pi), 0.0, 0.0])
        kids = [c for c in t.children(j) if np.linalg.norm(motion.offsets[c]) > 1e-9]
        if kids:
            d = motion.offsets[kids[0]] / np.linalg.norm(motion.offsets[kids[0]])
            align, _ = Rotation.align_vectors([d], [[1.0, 0.0, 0.0]])
            out.append((align * roll).as_matrix())
        else:
            out.append(Rotation.from_euler("ZXY", rng.uniform(-1, 1, 3)).as_matrix())
    return np.array(out)


def convert(motion: Motion, convention: str) -> Motion:
    """`motion` (a CMU clip) rewritten in `convention` (one of `CONVENTIONS`)."""
    if convention == "scrambled":
        return rename(motion, [f"j{i}" for i in range(motion.num_joints)])
    if convention == "metres":
        s = CMU_METRES_PER_UNIT
        t = motion.topology
        scale = np.array([s if c.endswith("position") else 1.0 for chans in t.channels for c in chans])
        return dataclasses.replace(motion, offsets=motion.offsets * s, end_site_offsets=motion.end_site_offsets * s,
                                   channels=motion.channels * scale)
    if convention == "zup":
        J = motion.num_joints
        return from_y_up(reframe(motion, np.broadcast_to(np.eye(3), (J, 3, 3)), "XYZ"), "z")
    renamed = rename(motion, convention_names(motion.topology, convention))
    if convention == "bandai":
        return reframe(renamed, _bone_along_x(motion), "ZXY")
    return renamed


def undo(positions: np.ndarray, convention: str) -> np.ndarray:
    """World positions `[..., 3]` of a converted clip mapped back to the CMU clip's axes and units."""
    if convention == "zup":
        return positions @ up_rotation("z").T
    if convention == "metres":
        return positions / CMU_METRES_PER_UNIT
    return positions


def scale_units(motion: Motion, factor: float) -> Motion:
    """`motion` with every length (offsets, End Sites, position channels) times `factor` (a clip in
    centimetres turned into metres: 0.01); the motion is the same."""
    t = motion.topology
    scale = np.array([factor if c.endswith("position") else 1.0 for chans in t.channels for c in chans])
    return dataclasses.replace(motion, offsets=motion.offsets * factor,
                               end_site_offsets=motion.end_site_offsets * factor, channels=motion.channels * scale)
