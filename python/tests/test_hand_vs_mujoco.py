"""`vge.Hand` against MuJoCo itself: the same hand file read by vge's reader and by MuJoCo gives
the same fingertip positions, fingertip Jacobians, body poses and masses at 1,000 random
configurations; and what vge refuses raises `vge.HandError` naming the element and line."""

from __future__ import annotations

import re
import struct
from pathlib import Path

import mujoco
import numpy as np
import pytest

import vge

REPO = Path(__file__).resolve().parents[2]
FIXTURES = REPO / "hand/tests/fixtures"
HANDS = [
    REPO / "hands/vge15.xml",
    REPO / "hands/allegro.xml",
    # Degrees, nested classes, childclass, autolimits, a non-normalised quat, fingertips as
    # bodies, visual meshes (their files do not exist: MuJoCo gets stand-ins, vge never opens
    # them).
    FIXTURES / "menagerie_style.xml",
    # Every orientation form with a fixed-axes eulerseq, two hinges in one body, fingertip sites
    # found by their `fingertip` prefix (no TOML).
    FIXTURES / "orientations.xml",
]


def _stand_in_mesh(name: str) -> bytes:
    """A small tetrahedron as an STL or OBJ file, for meshes MuJoCo insists on opening."""
    v = [(0, 0, 0), (0.01, 0, 0), (0, 0.01, 0), (0, 0, 0.01)]
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    if name.endswith(".obj"):
        lines = [f"v {x} {y} {z}" for x, y, z in v] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
        return ("\n".join(lines) + "\n").encode()
    out = b"\0" * 80 + struct.pack("<I", len(faces))
    for face in faces:
        out += struct.pack("<3f", 0, 0, 0) + b"".join(struct.pack("<3f", *v[i]) for i in face) + b"\0\0"
    return out


def _mujoco_model(path: Path) -> mujoco.MjModel:
    xml = path.read_text()
    meshes = re.findall(r'<mesh\b[^>]*\bfile="([^"]+)"', xml)
    if not meshes:
        return mujoco.MjModel.from_xml_path(str(path))
    return mujoco.MjModel.from_xml_string(xml, assets={m: _stand_in_mesh(m) for m in meshes})


def _random_q(hand: vge.Hand, rng: np.random.Generator) -> np.ndarray:
    limits = hand.joint_limits
    lo = np.where(np.isfinite(limits[:, 0]), limits[:, 0], -np.pi)
    hi = np.where(np.isfinite(limits[:, 1]), limits[:, 1], np.pi)
    return rng.uniform(lo, hi)


@pytest.fixture(params=HANDS, ids=lambda p: p.stem)
def hand_and_model(request):
    path = request.param
    if not path.is_file():
        pytest.fail(f"{path} is missing")
    return vge.Hand.load(path), _mujoco_model(path)


def test_names_limits_and_fingers_are_mujocos(hand_and_model):
    hand, m = hand_and_model
    # A hand-only model: the joint vector is MuJoCo's qpos.
    assert m.nq == m.nv == hand.num_joints
    for k, name in enumerate(hand.joint_names):
        j = m.joint(name)
        assert (j.qposadr[0], j.dofadr[0]) == (k, k), name
        if m.jnt_limited[j.id]:
            np.testing.assert_allclose(hand.joint_limits[k], m.jnt_range[j.id], rtol=0, atol=1e-6)
        else:
            assert np.isinf(hand.joint_limits[k]).all()
    assert len(hand.fingertip_names) == len(hand.finger_names) == hand.num_fingers
    assert hand.body_names == [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(m.nbody)]


def test_masses_and_inertias_are_mujocos(hand_and_model):
    hand, m = hand_and_model
    masses, coms, inertias = hand.body_mass_properties()
    np.testing.assert_allclose(masses, m.body_mass, rtol=1e-5, atol=1e-9)
    for b in range(m.nbody):
        if m.body_mass[b] == 0:
            continue
        np.testing.assert_allclose(coms[b], m.body_ipos[b], rtol=0, atol=1e-7)
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, m.body_iquat[b])
        rot = rot.reshape(3, 3)
        tensor = rot @ np.diag(m.body_inertia[b]) @ rot.T
        np.testing.assert_allclose(inertias[b], tensor, rtol=1e-4, atol=1e-11)


def test_kinematics_equal_mujoco_at_1000_random_configurations(hand_and_model):
    hand, m = hand_and_model
    d = mujoco.MjData(m)
    rng = np.random.default_rng(20240611)
    n = hand.num_joints
    dofs = [m.joint(name).dofadr[0] for name in hand.joint_names]
    sites = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, t) for t in hand.fingertip_names]
    bodies = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, t) for t in hand.fingertip_names]
    jacp = np.zeros((3, m.nv))
    worst_pos = worst_jac = worst_body = 0.0
    for _ in range(1000):
        q = _random_q(hand, rng)
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)  # mj_jac needs the subtree centres of mass
        tips = hand.fingertip_positions(q)
        jacobians = hand.fingertip_jacobians(q)
        assert tips.shape == (hand.num_fingers, 3)
        assert jacobians.shape == (hand.num_fingers, 3, n)
        for f in range(hand.num_fingers):
            if sites[f] >= 0:
                expected = d.site_xpos[sites[f]]
                mujoco.mj_jacSite(m, d, jacp, None, sites[f])
            else:
                expected = d.xpos[bodies[f]]
                mujoco.mj_jacBody(m, d, jacp, None, bodies[f])
            worst_pos = max(worst_pos, np.abs(tips[f] - expected).max())
            worst_jac = max(worst_jac, np.abs(jacobians[f] - jacp[:, dofs]).max())
        poses = hand.body_poses(q)
        worst_body = max(worst_body, np.abs(poses[:, :3] - d.xpos).max())
        # q and -q are one rotation.
        same = np.minimum(np.abs(poses[:, 3:] - d.xquat).max(axis=1), np.abs(poses[:, 3:] + d.xquat).max(axis=1))
        worst_body = max(worst_body, same.max())
    assert worst_pos < 1e-5, f"fingertip positions differ by up to {worst_pos} m"
    assert worst_jac < 1e-4, f"Jacobian entries differ by up to {worst_jac}"
    assert worst_body < 1e-5, f"body poses differ by up to {worst_body}"


def test_each_finger_moves_only_with_its_own_joints():
    hand = vge.Hand.load(REPO / "hands/vge15.xml")
    jacobians = hand.fingertip_jacobians(np.full(hand.num_joints, 0.2))
    for f, (start, end) in enumerate(hand.finger_joints):
        others = np.delete(jacobians[f], np.s_[start:end], axis=1)
        assert not others.any()
        assert np.abs(jacobians[f][:, start:end]).min(axis=0).max() > 0


ONE_FINGER = """<mujoco>
  <compiler angle="radian"/>
  <worldbody>
    <body name="prox">
      <joint name="j0" axis="0 1 0" range="-1 1"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.05" size="0.01"/>
      <body name="dist" pos="0 0 -0.05">
        <joint name="j1" axis="0 1 0" range="-1 1"/>
        <site name="fingertip"/>
{inside}
      </body>
    </body>
  </worldbody>
{after}
</mujoco>
"""


@pytest.mark.parametrize(
    "inside, after, marker, element",
    [
        ("", '  <tendon>\n    <fixed name="t">\n      <joint joint="j0" coef="1"/>\n    </fixed>\n  </tendon>', "<fixed", "fixed"),
        ('        <joint name="wobble" type="ball"/>', "", "wobble", "joint"),
        ("", '  <equality>\n    <joint name="mimic" joint1="j0" joint2="j1"/>\n  </equality>', "mimic", "joint"),
        ('        <freejoint name="loose"/>', "", "loose", "freejoint"),
        ('        <geom name="shell" type="mesh" mesh="absent"/>', "", "shell", "geom"),
        ("        <wibble/>", "", "wibble", "wibble"),
    ],
    ids=["tendon", "ball", "equality", "freejoint", "colliding-mesh", "unknown"],
)
def test_what_vge_refuses_raises_hand_error_naming_element_and_line(tmp_path, inside, after, marker, element):
    xml = ONE_FINGER.format(inside=inside, after=after)
    path = tmp_path / "refused.xml"
    path.write_text(xml)
    line = next(i for i, text in enumerate(xml.splitlines(), 1) if marker in text)
    with pytest.raises(vge.HandError, match=re.escape(f"{path}:{line}: <{element}>")) as caught:
        vge.Hand.load(path)
    assert isinstance(caught.value, ValueError)
    assert "outside vge's MJCF subset" in str(caught.value)


def test_bad_arguments_and_files_raise_the_usual_errors(tmp_path):
    hand = vge.Hand.load(REPO / "hands/vge15.xml")
    with pytest.raises(ValueError, match="shape"):
        hand.fingertip_positions(np.zeros(3))
    q = np.zeros(hand.num_joints)
    q[4] = np.nan
    with pytest.raises(ValueError, match="joint angle 4 is not finite"):
        hand.fingertip_jacobians(q)
    with pytest.raises(FileNotFoundError):
        vge.Hand.load(tmp_path / "absent.xml")
    with pytest.raises(OSError, match="not a regular file"):
        vge.Hand.load(tmp_path)
