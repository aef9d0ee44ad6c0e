#!/usr/bin/env python3
"""Writes franka_ridgeback/franka_ridgeback.urdf, franka_pedestal/franka_pedestal.urdf and
spot_arm/spot_arm.urdf.

The models are this project's own: primitive geometry (box, cylinder, sphere), kinematics, limits
and masses from the manufacturers' public figures (see README.md for every number's source).
Run from assets/robots/: `python3 generate_models.py`. Standard library only.
"""
import math
import os

PI = math.pi


def f(x):
    s = f"{x:.6g}"
    return "0" if s == "-0" else s


def v3(v):
    return " ".join(f(x) for x in v)


def box_inertia(m, sx, sy, sz):
    return (m * (sy * sy + sz * sz) / 12, m * (sx * sx + sz * sz) / 12, m * (sx * sx + sy * sy) / 12)


def cyl_inertia(m, r, length, axis="z"):
    ia = m * r * r / 2
    it = m * (3 * r * r + length * length) / 12
    return {"x": (ia, it, it), "y": (it, ia, it), "z": (it, it, ia)}[axis]


def sphere_inertia(m, r):
    i = 2 * m * r * r / 5
    return (i, i, i)


AXIS_RPY = {"x": (0, PI / 2, 0), "y": (PI / 2, 0, 0), "z": (0, 0, 0)}


class Urdf:
    def __init__(self, name, comment):
        self.lines = ['<?xml version="1.0"?>', f"<!-- {comment} -->", f'<robot name="{name}">']

    def link(self, name, inertial=None, shapes=(), rgba=None):
        """inertial: (mass, com xyz, (ixx, iyy, izz), full tensor (ixx,ixy,ixz,iyy,iyz,izz) or None)"""
        out = [f'  <link name="{name}">']
        if inertial is not None:
            m, com, diag, full = inertial
            if full is None:
                full = (diag[0], 0, 0, diag[1], 0, diag[2])
            out += [
                "    <inertial>",
                f'      <origin xyz="{v3(com)}" rpy="0 0 0"/>',
                f'      <mass value="{f(m)}"/>',
                '      <inertia ixx="{}" ixy="{}" ixz="{}" iyy="{}" iyz="{}" izz="{}"/>'.format(*map(f, full)),
                "    </inertial>",
            ]
        for geom, xyz, rpy in shapes:
            for tag in ("visual", "collision"):
                out.append(f"    <{tag}>")
                out.append(f'      <origin xyz="{v3(xyz)}" rpy="{v3(rpy)}"/>')
                out.append(f"      <geometry>{geom}</geometry>")
                if tag == "visual" and rgba is not None:
                    out.append(f'      <material name="{name}_colour"><color rgba="{v3(rgba)}"/></material>')
                out.append(f"    </{tag}>")
        out.append("  </link>")
        self.lines += out

    def joint(self, name, kind, parent, child, xyz=(0, 0, 0), rpy=(0, 0, 0), axis=None,
              limit=None, damping=None, mimic=None):
        out = [f'  <joint name="{name}" type="{kind}">',
               f'    <parent link="{parent}"/>', f'    <child link="{child}"/>',
               f'    <origin xyz="{v3(xyz)}" rpy="{v3(rpy)}"/>']
        if axis is not None:
            out.append(f'    <axis xyz="{v3(axis)}"/>')
        if limit is not None:
            lo, hi, effort, vel = limit
            if lo is None:
                out.append(f'    <limit effort="{f(effort)}" velocity="{f(vel)}"/>')
            else:
                out.append(f'    <limit lower="{f(lo)}" upper="{f(hi)}" effort="{f(effort)}" velocity="{f(vel)}"/>')
        if damping is not None:
            out.append(f'    <dynamics damping="{f(damping)}" friction="0"/>')
        if mimic is not None:
            out.append(f'    <mimic joint="{mimic[0]}" multiplier="{f(mimic[1])}" offset="0"/>')
        out.append("  </joint>")
        self.lines += out

    def write(self, path):
        self.lines.append("</robot>")
        with open(path, "w") as fh:
            fh.write("\n".join(self.lines) + "\n")


def box(s):
    return f'<box size="{v3(s)}"/>'


def cyl(r, length):
    return f'<cylinder radius="{f(r)}" length="{f(length)}"/>'


def sph(r):
    return f'<sphere radius="{f(r)}"/>'


def franka_arm(u, mount):
    """The Franka Panda arm with its hand (panda_link0 .. panda_link7, hand, TCP, two fingers),
    panda_link0 fixed to the link `mount`."""
    # Franka arm: link0 .. link7 with the inertial parameters of franka_description
    # (example-robot-data 6.0.0 panda_description), modified-DH kinematics of the Franka docs.
    inertials = {
        "panda_link0": (0.629769, (-0.041018, -0.00014, 0.049974), (0.00315, 8.2904e-07, 0.00015, 0.00388, 8.2299e-06, 0.004285)),
        "panda_link1": (4.970684, (0.003875, 0.002081, -0.04762), (0.70337, -0.000139, 0.006772, 0.70661, 0.019169, 0.009117)),
        "panda_link2": (0.646926, (-0.003141, -0.02872, 0.003495), (0.007962, -0.003925, 0.010254, 0.02811, 0.000704, 0.025995)),
        "panda_link3": (3.228604, (0.027518, 0.039252, -0.066502), (0.037242, -0.004761, -0.011396, 0.036155, -0.012805, 0.01083)),
        "panda_link4": (3.587895, (-0.05317, 0.104419, 0.027454), (0.025853, 0.007796, -0.001332, 0.019552, 0.008641, 0.028323)),
        "panda_link5": (1.225946, (-0.011953, 0.041065, -0.038437), (0.035549, -0.002117, -0.004037, 0.029474, 0.000229, 0.008627)),
        "panda_link6": (1.666555, (0.060149, -0.014117, -0.010517), (0.001964, 0.000109, -0.001158, 0.004354, 0.000341, 0.005433)),
        "panda_link7": (0.735522, (0.010517, -0.004252, 0.061597), (0.012516, -0.000428, -0.001196, 0.010027, -0.000741, 0.004815)),
    }
    # Collision primitives (chosen here, sizes after the capsule model of franka_description).
    shapes = {
        "panda_link0": [(cyl(0.07, 0.14), (-0.03, 0, 0.07), (0, 0, 0))],
        "panda_link1": [(cyl(0.06, 0.20), (0, 0, -0.17), (0, 0, 0))],
        "panda_link2": [(cyl(0.06, 0.12), (0, 0, 0), (0, 0, 0))],
        "panda_link3": [(cyl(0.06, 0.15), (0, 0, -0.12), (0, 0, 0))],
        "panda_link4": [(cyl(0.06, 0.12), (0, 0, 0), (0, 0, 0))],
        "panda_link5": [(cyl(0.06, 0.10), (0, 0, -0.24), (0, 0, 0)), (cyl(0.04, 0.14), (0, 0.08, -0.12), (0, 0, 0))],
        "panda_link6": [(cyl(0.06, 0.08), (0, 0, -0.03), (0, 0, 0))],
        "panda_link7": [(cyl(0.05, 0.12), (0, 0, 0.02), (0, 0, 0))],
    }
    u.link("panda_link0", (inertials["panda_link0"][0], inertials["panda_link0"][1], None, inertials["panda_link0"][2]),
           shapes["panda_link0"], rgba=(0.9, 0.9, 0.9, 1))
    u.joint("panda_mount", "fixed", mount, "panda_link0")
    # (name, xyz, rpy, lower, upper, effort, velocity) -- Franka datasheet limits.
    joints = [
        ("panda_joint1", (0, 0, 0.333), (0, 0, 0), -2.8973, 2.8973, 87, 2.175),
        ("panda_joint2", (0, 0, 0), (-PI / 2, 0, 0), -1.7628, 1.7628, 87, 2.175),
        ("panda_joint3", (0, -0.316, 0), (PI / 2, 0, 0), -2.8973, 2.8973, 87, 2.175),
        ("panda_joint4", (0.0825, 0, 0), (PI / 2, 0, 0), -3.0718, -0.0698, 87, 2.175),
        ("panda_joint5", (-0.0825, 0.384, 0), (-PI / 2, 0, 0), -2.8973, 2.8973, 12, 2.61),
        ("panda_joint6", (0, 0, 0), (PI / 2, 0, 0), -0.0175, 3.7525, 12, 2.61),
        ("panda_joint7", (0.088, 0, 0), (PI / 2, 0, 0), -2.8973, 2.8973, 12, 2.61),
    ]
    for i, (name, xyz, rpy, lo, hi, eff, vel) in enumerate(joints, start=1):
        child = f"panda_link{i}"
        m, com, full = inertials[child]
        u.link(child, (m, com, None, full), shapes[child], rgba=(0.9, 0.9, 0.9, 1))
        u.joint(name, "revolute", f"panda_link{i - 1}", child, xyz=xyz, rpy=rpy, axis=(0, 0, 1),
                limit=(lo, hi, eff, vel), damping=0.1)
    # Flange (d = 0.107) and hand, rotated -pi/4 about z; hand 0.73 kg.
    u.link("panda_hand", (0.73, (-0.01, 0, 0.03), None, (0.001, 0, 0, 0.0025, 0, 0.0017)),
           [(box((0.06, 0.20, 0.06)), (0, 0, 0.03), (0, 0, 0))], rgba=(0.9, 0.9, 0.9, 1))
    u.joint("panda_hand_joint", "fixed", "panda_link7", "panda_hand", xyz=(0, 0, 0.107), rpy=(0, 0, -PI / 4))
    u.link("panda_hand_tcp")
    u.joint("panda_hand_tcp_joint", "fixed", "panda_hand", "panda_hand_tcp", xyz=(0, 0, 0.1034))
    # Fingers: 0.015 kg each, travel 0 .. 0.04 m, 100 N, 0.2 m/s (franka_description).
    fm = 0.015
    fs = (0.02, 0.02, 0.05)
    for side, sign in (("left", 1), ("right", -1)):
        u.link(f"panda_{side}finger", (fm, (0, sign * 0.01, 0.025), box_inertia(fm, *fs), None),
               [(box(fs), (0, sign * 0.01, 0.025), (0, 0, 0))], rgba=(0.2, 0.2, 0.2, 1))
    u.joint("panda_finger_joint1", "prismatic", "panda_hand", "panda_leftfinger", xyz=(0, 0, 0.0584),
            axis=(0, 1, 0), limit=(0, 0.04, 100, 0.2), damping=0.3)
    u.joint("panda_finger_joint2", "prismatic", "panda_hand", "panda_rightfinger", xyz=(0, 0, 0.0584),
            axis=(0, -1, 0), limit=(0, 0.04, 100, 0.2), damping=0.3, mimic=("panda_finger_joint1", 1.0))


def franka_ridgeback():
    u = Urdf("franka_ridgeback",
             "Franka Panda on a Clearpath Ridgeback, primitive geometry; written by modesuite "
             "(assets/robots/generate_models.py), numbers and sources in assets/robots/README.md")
    # Virtual holonomic base: world -> x -> y -> yaw. Virtual links are massless frames.
    u.link("world")
    u.link("base_x_link")
    u.link("base_y_link")
    # Ridgeback max velocity 1.1 m/s, 2.0 rad/s (ridgeback_control control.yaml). Efforts: chassis +
    # arm (about 155 kg) at the 2.5 m/s^2 acceleration limit of control.yaml gives about 400 N.
    u.joint("base_x", "prismatic", "world", "base_x_link", axis=(1, 0, 0),
            limit=(-50, 50, 400, 1.1), damping=0)
    u.joint("base_y", "prismatic", "base_x_link", "base_y_link", axis=(0, 1, 0),
            limit=(-50, 50, 400, 1.1), damping=0)
    # Yaw: about 25 kg m^2 about z (chassis box + arm); 100 N m gives 4 rad/s^2.
    u.joint("base_yaw", "continuous", "base_y_link", "base_link", axis=(0, 0, 1),
            limit=(None, None, 100, 2.0), damping=0)
    # Chassis: 0.96 x 0.79 x 0.30 m, 135 kg (Clearpath published figures); top plate (mid_mount)
    # at z 0.3059 above the floor as in the ridgeback description.
    top = 0.3059
    sx, sy, sz = 0.96, 0.79, 0.30
    u.link("base_link", (135.0, (0, 0, top - sz / 2), box_inertia(135.0, sx, sy, sz), None),
           [(box((sx, sy, sz)), (0, 0, top - sz / 2), (0, 0, 0))], rgba=(0.15, 0.15, 0.15, 1))
    u.link("arm_mount")
    u.joint("arm_mount_joint", "fixed", "base_link", "arm_mount", xyz=(0.21, 0, top))
    franka_arm(u, "arm_mount")
    u.write("franka_ridgeback/franka_ridgeback.urdf")


def franka_pedestal():
    u = Urdf("franka_pedestal",
             "Franka Panda on a fixed pedestal, primitive geometry; written by modesuite "
             "(assets/robots/generate_models.py), numbers and sources in assets/robots/README.md")
    # Pedestal: a 0.3 x 0.3 x 0.5 m steel column, 40 kg (chosen here), the URDF's root: it is
    # fixed to the world at the spawn pose, so nothing moves it. The arm stands on its top.
    h = 0.5
    u.link("pedestal", (40.0, (0, 0, h / 2), box_inertia(40.0, 0.3, 0.3, h), None),
           [(box((0.3, 0.3, h)), (0, 0, h / 2), (0, 0, 0))], rgba=(0.3, 0.3, 0.32, 1))
    u.link("arm_mount")
    u.joint("arm_mount_joint", "fixed", "pedestal", "arm_mount", xyz=(0, 0, h))
    franka_arm(u, "arm_mount")
    u.write("franka_pedestal/franka_pedestal.urdf")


def spot_arm():
    u = Urdf("spot_arm",
             "Boston Dynamics Spot with Spot Arm, primitive geometry; written by modesuite "
             "(assets/robots/generate_models.py), numbers and sources in assets/robots/README.md")
    # Body: trunk 0.85 x 0.24 x 0.18 plus nose and tail blocks: overall length 1.1 m (BD figure).
    # Body mass 16.708 kg (BD spot_with_arm.urdf); inertia of the trunk box.
    bm = 16.708
    u.link("body", (bm, (0, 0, -0.015), box_inertia(bm, 0.85, 0.24, 0.18), None),
           [(box((0.85, 0.24, 0.18)), (0, 0, -0.015), (0, 0, 0)),
            (box((0.125, 0.20, 0.12)), (0.4875, 0, -0.015), (0, 0, 0)),
            (box((0.125, 0.20, 0.12)), (-0.4875, 0, -0.015), (0, 0, 0))], rgba=(0.95, 0.8, 0.1, 1))
    hip_m, uleg_m, lleg_m = 1.137, 2.256, 0.330
    foot_r = 0.036
    for leg, sx, sy in (("fl", 1, 1), ("fr", 1, -1), ("hl", -1, 1), ("hr", -1, -1)):
        u.link(f"{leg}_hip", (hip_m, (0, sy * 0.055, 0), cyl_inertia(hip_m, 0.05, 0.11, "y"), None),
               [(cyl(0.05, 0.11), (0, sy * 0.055, 0), AXIS_RPY["y"])], rgba=(0.2, 0.2, 0.2, 1))
        u.joint(f"{leg}_hx", "revolute", "body", f"{leg}_hip", xyz=(sx * 0.29785, sy * 0.055, 0),
                axis=(1, 0, 0), limit=(-0.785398, 0.785398, 45, 17.647), damping=0.2)
        u.link(f"{leg}_uleg", (uleg_m, (0, 0, -0.16), cyl_inertia(uleg_m, 0.045, 0.32), None),
               [(cyl(0.045, 0.32), (0, 0, -0.16), (0, 0, 0))], rgba=(0.95, 0.8, 0.1, 1))
        u.joint(f"{leg}_hy", "revolute", f"{leg}_hip", f"{leg}_uleg", xyz=(0, sy * 0.110945, 0),
                axis=(0, 1, 0), limit=(-0.898845, 2.295108, 45, 17.647), damping=0.2)
        # Lower leg: shank cylinder plus the spherical foot (r 0.036 at 0.3365 below the knee).
        shank_i = cyl_inertia(lleg_m, 0.015, 0.32)
        u.link(f"{leg}_lleg", (lleg_m, (0, 0, -0.16), shank_i, None),
               [(cyl(0.015, 0.30), (0, 0, -0.15), (0, 0, 0)),
                (sph(foot_r), (0, 0, -0.3365), (0, 0, 0))], rgba=(0.2, 0.2, 0.2, 1))
        u.joint(f"{leg}_kn", "revolute", f"{leg}_uleg", f"{leg}_lleg", xyz=(0.025, 0, -0.3205),
                axis=(0, 1, 0), limit=(-2.7929, -0.2471, 115, 12.0), damping=0.2)
        u.link(f"{leg}_foot")
        u.joint(f"{leg}_foot_joint", "fixed", f"{leg}_lleg", f"{leg}_foot", xyz=(0, 0, -0.3365))
    # Arm (BD spot_with_arm.urdf joint origins, limits, efforts and link masses; 10 rad/s).
    arm = [
        # name, parent, child, xyz, axis, lower, upper, effort, mass, shape (geom, xyz, rpy), inertia
        ("arm_sh0", "body", "arm_link_sh0", (0.292, 0, 0.188), (0, 0, 1), -2.61799, 3.14159, 90.9, 1.905,
         (cyl(0.05, 0.10), (0, 0, -0.05), (0, 0, 0)), cyl_inertia(1.905, 0.05, 0.10)),
        ("arm_sh1", "arm_link_sh0", "arm_link_sh1", (0, 0, 0), (0, 1, 0), -3.14159, 0.523599, 181.8, 1.857,
         (cyl(0.04, 0.30), (0.17, 0, 0), AXIS_RPY["x"]), cyl_inertia(1.857, 0.04, 0.30, "x")),
        ("arm_el0", "arm_link_sh1", "arm_link_el0", (0.3385, 0, 0), (0, 1, 0), 0.0, 3.14159, 90.9, 0.948,
         (box((0.08, 0.07, 0.075)), (0.04, 0, 0.0375), (0, 0, 0)), box_inertia(0.948, 0.08, 0.07, 0.075)),
        ("arm_el1", "arm_link_el0", "arm_link_el1", (0.4033, 0, 0.075), (1, 0, 0), -2.79253, 2.79253, 30.3, 1.018,
         (cyl(0.035, 0.26), (-0.185, 0, 0), AXIS_RPY["x"]), cyl_inertia(1.018, 0.035, 0.26, "x")),
        ("arm_wr0", "arm_link_el1", "arm_link_wr0", (0, 0, 0), (0, 1, 0), -1.8326, 1.8326, 30.3, 0.583,
         (sph(0.035), (0, 0, 0), (0, 0, 0)), sphere_inertia(0.583, 0.035)),
        ("arm_wr1", "arm_link_wr0", "arm_link_wr1", (0, 0, 0), (1, 0, 0), -2.87979, 2.87979, 30.3, 0.933,
         (box((0.11, 0.07, 0.06)), (0.055, 0, 0), (0, 0, 0)), box_inertia(0.933, 0.11, 0.07, 0.06)),
    ]
    for name, parent, child, xyz, axis, lo, hi, eff, m, shape, inertia in arm:
        extra = []
        if child == "arm_link_wr1":
            # Fixed lower jaw of the gripper.
            extra = [(box((0.125, 0.05, 0.012)), (0.18, 0, -0.015), (0, 0, 0))]
        u.link(child, (m, shape[1], inertia, None), [shape] + extra, rgba=(0.95, 0.8, 0.1, 1))
        u.joint(name, "revolute", parent, child, xyz=xyz, axis=axis, limit=(lo, hi, eff, 10.0), damping=0.2)
    fm = 0.224
    u.link("arm_link_fngr", (fm, (0.0624, 0, 0.006), box_inertia(fm, 0.125, 0.05, 0.012), None),
           [(box((0.125, 0.05, 0.012)), (0.0624, 0, 0.006), (0, 0, 0))], rgba=(0.2, 0.2, 0.2, 1))
    u.joint("arm_f1x", "revolute", "arm_link_wr1", "arm_link_fngr", xyz=(0.11745, 0, 0.01482), axis=(0, 1, 0),
            limit=(-1.5708, 0.0, 15.32, 10.0), damping=0.1)
    u.link("arm_link_tool")
    u.joint("arm_tool_joint", "fixed", "arm_link_wr1", "arm_link_tool", xyz=(0.24227, 0, 0))
    u.write("spot_arm/spot_arm.urdf")


if __name__ == "__main__":
    os.chdir(os.path.dirname(os.path.abspath(__file__)))
    franka_ridgeback()
    franka_pedestal()
    spot_arm()
