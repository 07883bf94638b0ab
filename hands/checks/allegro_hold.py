"""Checks hands/allegro.xml in MuJoCo: the model, the grasp keyframe's geometry, and whether
the grasp holds a 65 mm cube under gravity.

    .deps/py/bin/python hands/checks/allegro_hold.py [--mass 0.1] [--friction 0.8]
        [--squeeze 0.05 | --press-mm 3 | --press-n-per-kg 5] [--thumb-squeeze S] [--noslip N]
        [--seconds 2] [--palm-up]

The scene is the hand file plus a cube on a free joint at the origin (the object vge adds).
The motor targets are the keyframe's joints pressed past contact, either as vge's own grasp
does (GraspConfig's squeeze_rad: the flexion joints, j1-j3 of every finger and thj2-thj3 of
the thumb, `--squeeze` rad further) or, with `--press-mm`, each finger's targets moved so that
its tip would go that far into its face (through the tip's Jacobian), or, with
`--press-n-per-kg`, as vge's start grasp does for a hand with a keyframe (sim/src/grasp.rs:
each tip pressing that many N per kg of the cube into its face, the thumb against the
fingers' resultant, the links' and the cube's weight carried). The cube is held still
for 0.05 s while the grip builds, then released. MuJoCo options as vge's sim-vs-MuJoCo
comparison: implicitfast, elliptic cones, impratio 10.

Measured (0.1 kg, friction 0.8, dt 2 ms, 2 s): --press-n-per-kg 5 holds it 1.1 mm lower,
0.1 mm off centre sideways, turned 0.9 deg (palm up: 0.8 mm, 0.3 deg); --press-mm 3 holds it
2.4 mm lower and 1.5 mm towards the thumb; --squeeze 0.05 holds it 3.2 mm lower and 5.6 mm
towards the thumb (the thumb's flexion presses mostly upwards); --squeeze 0 drops it. The
slow sinking that remains (about 0.5 mm/s) does not change with friction 0.8 or 1.5 and
stops with --noslip 3 (--press-n-per-kg 5: 0.01 mm in 10 s): it is the creep of MuJoCo's
soft friction constraints, not slip. The joints' damping (0.001 in the file, 0.1 before)
makes no difference here (--press-n-per-kg 5, 10 s: 5.26 and 5.25 mm lower).
"""

import argparse
from pathlib import Path

import mujoco
import numpy as np

HAND = Path(__file__).resolve().parents[1] / "allegro.xml"
TIPS = ["ff_tip", "mf_tip", "rf_tip", "th_tip"]
FLEXION = [1, 2, 3, 5, 6, 7, 9, 10, 11, 14, 15]


def hand_checks(m, d, key_q, half):
    """Model sizes, and the keyframe's distances to a cube of half-width `half`."""
    assert m.nq == m.nv == m.nu == 16, (m.nq, m.nv, m.nu)
    lo, hi = m.jnt_range.T
    margin = np.minimum(key_q - lo, hi - key_q)
    print(f"nq {m.nq} nv {m.nv} nu {m.nu}, hand mass {m.body_subtreemass[1]:.4f} kg")
    j = int(np.argmin(margin))
    print(f"grasp: smallest joint margin {margin[j]:.3f} rad ({m.joint(j).name})")
    spec = mujoco.MjSpec.from_file(str(HAND))
    spec.worldbody.add_geom(
        name="cube", type=mujoco.mjtGeom.mjGEOM_BOX, size=[half] * 3, contype=0, conaffinity=0
    )
    for k in list(spec.keys):
        spec.delete(k)
    mc = spec.compile()
    dc = mujoco.MjData(mc)
    dc.qpos[:] = key_q
    mujoco.mj_forward(mc, dc)
    cube = mc.geom("cube").id
    fromto = np.zeros(6)
    tip_ids = [mc.geom(t).id for t in TIPS]
    for t, g in zip(TIPS, tip_ids):
        dist = mujoco.mj_geomDistance(mc, dc, g, cube, 0.1, fromto)
        print(f"  {t}: centre {np.round(dc.geom_xpos[g], 4)}, surface {1e3 * dist:+.2f} mm from the cube")
    others = [
        (mujoco.mj_geomDistance(mc, dc, g, cube, 0.1, fromto), mc.geom(g).name)
        for g in range(mc.ngeom)
        if g != cube and g not in tip_ids
    ]
    dist, name = min(others)
    print(f"  nearest other hand geom: {name} {1e3 * dist:.1f} mm; hand self-contacts: {dc.ncon}")


def vge_press(m, d, key_q, force_n):
    """vge's start grasp (sim/src/grasp.rs): each tip pressing `force_n` into its face, the
    thumb against the fingers' resultant, the least change to those forces that carries the
    cube's weight and turns it about no axis; the targets are the pose plus (J^T f + the
    links' gravity torques) / kp."""
    mujoco.mj_forward(m, d)
    cube = m.body("cube").id
    centre = d.xpos[cube].copy()
    points, forces, jacs = [], [], []
    for t in TIPS:
        c = d.xpos[m.body(t).id] - centre
        axis = int(np.argmax(np.abs(c)))
        inward = np.zeros(3)
        inward[axis] = -np.sign(c[axis])
        p = c + inward * m.geom(t).size[0]
        points.append(p)
        forces.append(inward * force_n)
        jac = np.zeros((3, m.nv))
        mujoco.mj_jac(m, d, jac, None, p + centre, m.body(t).id)
        jacs.append(jac[:, :16])
    forces[3] = -sum(forces[:3])
    grasp_map = np.zeros((6, 12))
    for k, p in enumerate(points):
        grasp_map[:3, 3 * k : 3 * k + 3] = np.eye(3)
        grasp_map[3:, 3 * k : 3 * k + 3] = [[0, -p[2], p[1]], [p[2], 0, -p[0]], [-p[1], p[0], 0]]
    weight = m.opt.gravity * m.body_mass[cube]
    wanted = np.concatenate([-weight, np.zeros(3)])
    f = np.concatenate(forces)
    f += np.linalg.pinv(grasp_map, rcond=1e-6) @ (wanted - grasp_map @ f)
    torque = d.qfrc_bias[:16].copy()  # at rest: the links' gravity torques
    for k, jac in enumerate(jacs):
        torque += jac.T @ f[3 * k : 3 * k + 3]
    return key_q + torque / m.actuator_gainprm[:16, 0]


def hold(args, key_q, half):
    spec = mujoco.MjSpec.from_file(str(HAND))
    for k in list(spec.keys):
        spec.delete(k)
    spec.option.timestep = args.timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = 10
    spec.option.noslip_iterations = args.noslip
    if args.palm_up:
        palm = spec.body("palm")
        p = np.array(palm.pos)
        palm.pos = [p[0], -p[1], -p[2]]
        q = np.zeros(4)
        mujoco.mju_mulQuat(q, np.array([0.0, 1.0, 0.0, 0.0]), np.array(palm.quat))
        palm.quat = q
    body = spec.worldbody.add_body(name="cube")
    body.add_freejoint(name="cube")
    body.add_geom(
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[half] * 3,
        mass=args.mass,
        friction=[args.friction, 0.005, 0.0001],
    )
    for g in spec.geoms:
        if g.name in TIPS or g.name.endswith(("_distal", "_medial", "_proximal", "_base")) or g.name == "palm":
            g.friction = [args.friction, 0.005, 0.0001]
    m = spec.compile()
    d = mujoco.MjData(m)
    d.qpos[:16] = key_q
    d.qpos[16:23] = [0, 0, 0, 1, 0, 0, 0]
    ctrl = key_q.copy()
    if args.press_mm is None and args.press_n_per_kg is None:
        ctrl[FLEXION] += args.squeeze
        if args.thumb_squeeze is not None:
            ctrl[[14, 15]] += args.thumb_squeeze - args.squeeze
    elif args.press_n_per_kg is not None:
        ctrl = vge_press(m, d, key_q, args.press_n_per_kg * args.mass)
    else:
        # Each finger's targets moved so that its tip goes `press_mm` into its face (least
        # squares through the tip's Jacobian): a press along the face normal for every finger.
        mujoco.mj_forward(m, d)
        for f, t in enumerate(TIPS):
            jac = np.zeros((3, m.nv))
            mujoco.mj_jacBody(m, d, jac, None, m.body(t).id)
            c = d.xpos[m.body(t).id]
            axis = int(np.argmax(np.abs(c)))
            normal = np.zeros(3)
            normal[axis] = np.sign(c[axis])
            cols = slice(4 * f, 4 * f + 4)
            ctrl[cols] += np.linalg.pinv(jac[:, cols]) @ (-normal * args.press_mm * 1e-3)
    d.ctrl[:] = np.clip(ctrl, m.actuator_ctrlrange[:, 0], m.actuator_ctrlrange[:, 1])
    mujoco.mj_forward(m, d)
    hold_steps = round(0.05 / m.opt.timestep)
    for _ in range(hold_steps):
        d.qpos[16:23] = [0, 0, 0, 1, 0, 0, 0]
        d.qvel[16:22] = 0
        mujoco.mj_step(m, d)
    steps = round(args.seconds / m.opt.timestep)
    cube_body = m.body("cube").id
    tip_bodies = {m.body(t).id: t for t in TIPS}
    for i in range(steps):
        mujoco.mj_step(m, d)
        if (i + 1) % round(0.5 / m.opt.timestep) == 0 or i + 1 == steps:
            pos = d.qpos[16:19]
            quat = d.qpos[19:23]
            angle = 2 * np.arccos(min(1.0, abs(quat[0])))
            touching, other = set(), set()
            for c in d.contact[: d.ncon]:
                b1, b2 = m.geom_bodyid[c.geom1], m.geom_bodyid[c.geom2]
                if cube_body in (b1, b2):
                    b = b2 if b1 == cube_body else b1
                    (touching if b in tip_bodies else other).add(tip_bodies.get(b, m.body(b).name))
            force = np.abs(d.actuator_force)
            print(
                f"  t {(i + 1) * m.opt.timestep:.2f} s: cube at {np.round(1e3 * pos, 2)} mm, "
                f"turned {np.degrees(angle):.2f} deg; tips on the cube {sorted(touching)}"
                + (f", other links on it {sorted(other)}" if other else "")
                + f"; max |motor torque| {force.max():.3f} N*m"
            )
    drop = -d.qpos[18]
    held = np.linalg.norm(d.qpos[16:19]) < 0.02
    print(f"drop in z {1e3 * drop:.2f} mm; {'held' if held else 'NOT held'}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--width", type=float, default=0.065)
    ap.add_argument("--mass", type=float, default=0.1)
    ap.add_argument("--friction", type=float, default=0.8)
    ap.add_argument("--squeeze", type=float, default=0.05)
    ap.add_argument("--thumb-squeeze", type=float, default=None, help="the thumb's, if not --squeeze")
    ap.add_argument("--press-mm", type=float, default=None, help="press each tip this far into its face instead")
    ap.add_argument(
        "--press-n-per-kg", type=float, default=None,
        help="vge's start grasp instead: each tip pressing this many N per kg of the cube (GraspConfig's 5)",
    )
    ap.add_argument("--noslip", type=int, default=0, help="MuJoCo noslip iterations (0: off)")
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--timestep", type=float, default=0.002)
    ap.add_argument("--palm-up", action="store_true")
    args = ap.parse_args()
    m = mujoco.MjModel.from_xml_path(str(HAND))
    d = mujoco.MjData(m)
    key_q = m.key("grasp").qpos.copy()
    hand_checks(m, d, key_q, args.width / 2)
    print(
        f"hold: {args.width * 1e3:.0f} mm cube, {args.mass} kg, friction {args.friction}, "
        + (
            f"press {args.press_mm} mm"
            if args.press_mm is not None
            else f"press {args.press_n_per_kg} N/kg"
            if args.press_n_per_kg is not None
            else f"squeeze {args.squeeze} rad"
        )
        + f", dt {args.timestep} s, {'palm up' if args.palm_up else 'palm down'}"
    )
    hold(args, key_q, args.width / 2)


if __name__ == "__main__":
    main()
