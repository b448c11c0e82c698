#!/usr/bin/env python3
"""Writes the SDFormat models in ``models/`` from published numbers.

drake-skill cannot fetch Drake's remote ``drake_models`` package, so it ships
its own Franka Emika Panda, written here from:

* kinematics: Franka's published modified Denavit-Hartenberg table (Craig's
  convention, "Robot and interface specifications", Franka Control Interface
  documentation): frame i is reached from frame i-1 by
  ``RotX(alpha) * TransX(a) * TransZ(d)`` and then the joint rotates about z_i;
* joint limits: the same document (position, velocity, torque limits);
* link masses, centres of mass and inertias: C. Gaz, M. Cognetti, A. Oliva,
  P. Robuffo Giordano, A. De Luca, "Dynamic Identification of the Franka Emika
  Panda Robot With Retrieval of Feasible Parameters Using Penalty-Based
  Optimization", IEEE Robotics and Automation Letters 4(4), 2019;
* collision geometry: capsules and boxes sized to keep the real reach and
  clearances (link radii about 6 cm, hand 20 cm wide).

The scene objects (table, a blue box with a hinged lid and a front lip, a blue
drawer unit with a handle) are written here too, so that every dimension is in
one place. Run ``python tools/generate_models.py`` after changing a number; the
generated files are committed.
"""

from __future__ import annotations

import math

from drake_skill.resources import models_dir
from drake_skill.station import limits  # numpy only

PI = math.pi

# Franka's modified DH table: (a, d, alpha) for joints 1..7, then the flange.
DH = [
    (0.0, 0.333, 0.0),
    (0.0, 0.0, -PI / 2),
    (0.0, 0.316, PI / 2),
    (0.0825, 0.0, PI / 2),
    (-0.0825, 0.384, -PI / 2),
    (0.0, 0.0, PI / 2),
    (0.088, 0.0, PI / 2),
]
FLANGE_D = 0.107

# Joint limits: the one definition, shared with the controller and the hardware port.
Q_MIN, Q_MAX, QD_MAX, TAU_MAX = (limits.Q_MIN.tolist(), limits.Q_MAX.tolist(), limits.QD_MAX.tolist(),
                                 limits.TAU_MAX.tolist())

# Gaz et al. 2019, Table (feasible parameters): mass [kg], CoM in the link's DH
# frame [m], inertia about the CoM [kg m^2] as (xx, xy, xz, yy, yz, zz).
INERTIAL = {
    1: (4.970684, (3.875e-03, 2.081e-03, -4.762e-02),
        (7.0337e-01, -1.3900e-04, 6.7720e-03, 7.0661e-01, 1.9169e-02, 9.1170e-03)),
    2: (0.646926, (-3.141e-03, -2.872e-02, 3.495e-03),
        (7.9620e-03, -3.9250e-03, 1.0254e-02, 2.8110e-02, 7.0400e-04, 2.5995e-02)),
    3: (3.228604, (2.7518e-02, 3.9252e-02, -6.6502e-02),
        (3.7242e-02, -4.7610e-03, -1.1396e-02, 3.6155e-02, -1.2805e-02, 1.0830e-02)),
    4: (3.587895, (-5.317e-02, 1.04419e-01, 2.7454e-02),
        (2.5853e-02, 7.7960e-03, -1.3320e-03, 1.9552e-02, 8.6410e-03, 2.8323e-02)),
    5: (1.225946, (-1.1953e-02, 4.1065e-02, -3.8437e-02),
        (3.5549e-02, -2.1170e-03, -4.0370e-03, 2.9474e-02, 2.2900e-04, 8.6270e-03)),
    6: (1.666555, (6.0149e-02, -1.4117e-02, -1.0517e-02),
        (1.9640e-03, 1.0900e-04, -1.1580e-03, 4.3540e-03, 3.4100e-04, 5.4330e-03)),
    7: (7.35522e-01, (1.0517e-02, -4.252e-03, 6.1597e-02),
        (1.2516e-02, -4.2800e-04, -1.1960e-03, 1.0027e-02, -7.4100e-04, 4.8150e-03)),
}
# Link 0 (base) is welded to the table; its inertia does not enter the dynamics.
BASE_INERTIAL = (0.629769, (-4.1018e-02, -1.4e-04, 4.9974e-02),
                 (3.15e-03, 8.2904e-07, 1.5e-04, 3.88e-03, 8.2299e-06, 4.285e-03))

WHITE = "0.92 0.92 0.92 1"
DARK = "0.15 0.15 0.17 1"
BLUE = "0.10 0.25 0.80 1"
WOOD = "0.55 0.40 0.25 1"

# Capsules per link in the link's own DH frame: (p_start, p_end, radius).
# They follow the Panda's outline: a housing around each joint axis and a
# segment along each link, 5-6 cm in radius.
CAPSULES = {
    0: [((-0.04, 0.0, 0.03), (-0.04, 0.0, 0.12), 0.085)],
    1: [((0.0, 0.0, -0.19), (0.0, 0.0, -0.06), 0.06),
        ((0.0, -0.06, 0.0), (0.0, 0.06, 0.0), 0.06)],
    2: [((0.0, 0.0, -0.06), (0.0, 0.0, 0.06), 0.06),
        ((0.0, 0.0, 0.0), (0.0, -0.19, 0.0), 0.06)],
    3: [((0.0, 0.0, -0.14), (0.0, 0.0, -0.02), 0.06),
        ((0.0825, -0.055, 0.0), (0.0825, 0.055, 0.0), 0.055)],
    4: [((0.0, 0.0, -0.055), (0.0, 0.0, 0.055), 0.055),
        ((0.0, 0.0, 0.0), (-0.0825, 0.10, 0.0), 0.055)],
    5: [((0.0, 0.0, -0.26), (0.0, 0.0, -0.10), 0.055),
        ((0.0, 0.08, -0.10), (0.0, 0.08, -0.02), 0.035),
        ((0.0, 0.0, -0.06), (0.0, 0.0, -0.01), 0.045)],   # clear of link 7 at q_home
    6: [((0.0, 0.0, -0.04), (0.0, 0.0, 0.04), 0.05),
        ((0.0, 0.0, 0.0), (0.088, 0.0, 0.0), 0.045)],
    7: [((0.0, 0.0, -0.03), (0.0, 0.0, 0.08), 0.045)],
}


def _pose(xyz, rpy=(0.0, 0.0, 0.0)) -> str:
    return " ".join(f"{v:.6g}" for v in (*xyz, *rpy))


def _pose_exact(xyz, rpy) -> str:
    """A pose at full double precision (the DH angles: pi / 2 to every digit)."""
    return " ".join(repr(float(v)) for v in (*xyz, *rpy))


def _inertial(mass, com, inertia) -> str:
    ixx, ixy, ixz, iyy, iyz, izz = inertia
    return f"""      <inertial>
        <pose>{_pose(com)}</pose>
        <mass>{mass}</mass>
        <inertia><ixx>{ixx}</ixx><ixy>{ixy}</ixy><ixz>{ixz}</ixz><iyy>{iyy}</iyy><iyz>{iyz}</iyz><izz>{izz}</izz></inertia>
      </inertial>
"""


# Visual capsules are low-polygon meshes: the renderer's own capsules are
# finely tessellated, and with ~20 of them the arm dominated the camera's
# render time (colour 28 ms vs 18 ms per frame with boxes, on this machine).
CAPSULE_SIDES = 16
CAPSULE_RINGS = 4
MESHES: dict[str, str] = {}


def capsule_obj(radius: float, length: float, sides: int = CAPSULE_SIDES, rings: int = CAPSULE_RINGS) -> str:
    """Wavefront OBJ text of a capsule along z, centred at the origin."""
    verts, normals, faces = [], [], []
    rows = []   # (z of the hemisphere centre, latitude a) per ring, bottom pole to top pole
    for i in range(rings + 1):
        rows.append((-length / 2, -math.pi / 2 + (math.pi / 2) * i / rings))
    for i in range(rings + 1):
        rows.append((length / 2, (math.pi / 2) * i / rings))
    for zc, a in rows:
        for k in range(sides):
            t = 2 * math.pi * k / sides
            n = (math.cos(a) * math.cos(t), math.cos(a) * math.sin(t), math.sin(a))
            normals.append(n)
            verts.append((radius * n[0], radius * n[1], zc + radius * n[2]))
    for j in range(len(rows) - 1):
        for k in range(sides):
            a, b = j * sides + k, j * sides + (k + 1) % sides
            c, d = a + sides, b + sides
            faces += [(a, b, d), (a, d, c)]
    lines = [f"v {x:.5f} {y:.5f} {z:.5f}" for x, y, z in verts]
    lines += [f"vn {x:.5f} {y:.5f} {z:.5f}" for x, y, z in normals]
    lines += [f"f {a + 1}//{a + 1} {b + 1}//{b + 1} {c + 1}//{c + 1}" for a, b, c in faces]
    return "\n".join(lines) + "\n"


def _capsule(name, p0, p1, radius, color, collision=True) -> str:
    """A capsule from p0 to p1 (link frame): SDF visual (low-poly mesh) + collision (capsule)."""
    dx, dy, dz = (p1[i] - p0[i] for i in range(3))
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    centre = tuple((p0[i] + p1[i]) / 2 for i in range(3))
    # Rotate z onto the segment direction: pitch about y, then yaw about z.
    if length < 1e-9:
        rpy = (0.0, 0.0, 0.0)
    else:
        pitch = math.acos(max(-1.0, min(1.0, dz / length)))
        yaw = math.atan2(dy, dx)
        rpy = (0.0, pitch, yaw)
    mesh_name = f"meshes/{name}.obj"
    MESHES[mesh_name] = capsule_obj(radius, length)
    return _geometry(name, centre, rpy, color,
                     visual_geom=f"<mesh><uri>package://drake_skill_models/{mesh_name}</uri></mesh>",
                     collision_geom=(f"<capsule><radius>{radius}</radius><length>{length:.6g}</length></capsule>"
                                     if collision else None))


def _geometry(name, centre, rpy, color, visual_geom, collision_geom) -> str:
    """An SDF visual (when ``visual_geom``) and collision (when ``collision_geom``) at one pose.

    Contact parameters (friction, stiffness, dissipation) are not written here:
    the station sets them per surface from its scenario (``Scenario.contact``).
    """
    out = ""
    if visual_geom:
        out += f"""      <visual name="{name}_visual">
        <pose>{_pose(centre, rpy)}</pose>
        <geometry>{visual_geom}</geometry>
        <material><diffuse>{color}</diffuse></material>
      </visual>
"""
    if collision_geom:
        out += f"""      <collision name="{name}_collision">
        <pose>{_pose(centre, rpy)}</pose>
        <geometry>{collision_geom}</geometry>
      </collision>
"""
    return out


def _box(name, centre, size, color, rpy=(0.0, 0.0, 0.0), collision=True, visual=True) -> str:
    geom = "<box><size>{}</size></box>".format(" ".join(f"{s:.6g}" for s in size))
    return _geometry(name, centre, rpy, color, geom if visual else None, geom if collision else None)


def _cylinder(name, centre, radius, length, color, rpy=(0.0, 0.0, 0.0), collision=True) -> str:
    geom = f"<cylinder><radius>{radius}</radius><length>{length}</length></cylinder>"
    return _geometry(name, centre, rpy, color, geom, geom if collision else None)


def _box_inertia(mass, size):
    x, y, z = size
    return (mass * (y * y + z * z) / 12, 0.0, 0.0, mass * (x * x + z * z) / 12, 0.0,
            mass * (x * x + y * y) / 12)


def _sdf(model_name: str, body: str, comment: str) -> str:
    return f"""<?xml version="1.0"?>
<!-- {comment}
     Generated by tools/generate_models.py; edit that script, not this file. -->
<sdf version="1.9" xmlns:drake="http://drake.mit.edu">
  <model name="{model_name}">
{body}  </model>
</sdf>
"""


def panda_arm() -> str:
    body = f"""    <link name="panda_link0">
{_inertial(*BASE_INERTIAL)}"""
    for cap_i, (p0, p1, r) in enumerate(CAPSULES[0]):
        body += _capsule(f"link0_{cap_i}", p0, p1, r, WHITE)
    body += "    </link>\n"
    for i, (a, d, alpha) in enumerate(DH, start=1):
        xyz = tuple(0.0 if abs(v) < 1e-12 else v for v in (a, -d * math.sin(alpha), d * math.cos(alpha)))
        body += f"""    <link name="panda_link{i}">
      <pose relative_to="panda_joint{i}"/>
{_inertial(*INERTIAL[i])}"""
        for cap_i, (p0, p1, r) in enumerate(CAPSULES[i]):
            color = DARK if (i == 7 and cap_i == 0) else WHITE
            body += _capsule(f"link{i}_{cap_i}", p0, p1, r, color)
        body += f"""    </link>
    <joint name="panda_joint{i}" type="revolute">
      <pose relative_to="panda_link{i - 1}">{_pose_exact(xyz, (alpha, 0.0, 0.0))}</pose>
      <parent>panda_link{i - 1}</parent>
      <child>panda_link{i}</child>
      <axis>
        <xyz>0 0 1</xyz>
        <limit>
          <lower>{Q_MIN[i - 1]}</lower><upper>{Q_MAX[i - 1]}</upper>
          <velocity>{QD_MAX[i - 1]}</velocity><effort>{TAU_MAX[i - 1]}</effort>
        </limit>
        <dynamics><damping>0.0</damping></dynamics>
      </axis>
    </joint>
"""
    body += f"""    <frame name="panda_link8" attached_to="panda_link7">
      <pose relative_to="panda_link7">0 0 {FLANGE_D} 0 0 0</pose>
    </frame>
"""
    return _sdf("panda", body,
                "Franka Emika Panda arm: DH kinematics and limits from Franka's "
                "published specifications; masses and inertias from Gaz et al., "
                "IEEE RA-L 2019; primitive collision geometry.")


# The Franka Hand: fingers 5.84 cm past the flange-side face, 0-4 cm travel each,
# the tool centre point (TCP) 10.34 cm from the hand frame along z.
FINGER_Z = 0.0584
FINGER_SIZE = (0.022, 0.018, 0.054)   # x (thickness), y (inward face), z (length)
TCP_Z = 0.1034
# The hand's inertia about its CoM (xx, xy, xz, yy, yz, zz) [kg m^2]: the
# largest moment is about x_H, across the 0.20 m span of the fingers' y axis
# (as a 0.055 x 0.20 x 0.06 m box of 0.73 kg would have it), the smallest
# about y_H.
HAND_INERTIA = (0.0025, 0.0, 0.0, 0.001, 0.0, 0.0017)
# The dark flange plate (visual only) sits 0.5 mm below the hand body's bottom
# face: with the two faces coplanar the renderer picks either colour per pixel
# by depth-buffer rounding, and a cropped camera's pixels differ from the full
# frame's there (issue 11).
HAND_BASE_Z = 0.0045


def panda_hand() -> str:
    hand_inertial = _inertial(0.73, (-0.01, 0.0, 0.03), HAND_INERTIA)
    hand_geometry = (_box("hand_body", (0, 0, 0.03), (0.055, 0.20, 0.06), WHITE)
                     + _box("hand_base", (0, 0, HAND_BASE_Z), (0.06, 0.07, 0.01), DARK, collision=False))
    body = f"""    <link name="panda_hand">
{hand_inertial}{hand_geometry}    </link>
    <frame name="panda_tcp" attached_to="panda_hand">
      <pose relative_to="panda_hand">0 0 {TCP_Z} 0 0 0</pose>
    </frame>
"""
    for side, sign in (("left", 1.0), ("right", -1.0)):
        cx = 0.0
        cy = sign * FINGER_SIZE[1] / 2
        cz = FINGER_SIZE[2] / 2
        finger_inertial = _inertial(0.015, (0, cy, cz), (2.375e-06, 0.0, 0.0, 2.375e-06, 0.0, 7.5e-07))
        finger_box = _box(f"{side}finger", (cx, cy, cz), FINGER_SIZE, DARK)
        body += f"""    <link name="panda_{side}finger">
      <pose relative_to="panda_finger_joint_{side}"/>
{finger_inertial}{finger_box}    </link>
    <joint name="panda_finger_joint_{side}" type="prismatic">
      <pose relative_to="panda_hand">0 0 {FINGER_Z} 0 0 0</pose>
      <parent>panda_hand</parent>
      <child>panda_{side}finger</child>
      <axis>
        <xyz>0 {sign:.0f} 0</xyz>
        <limit><lower>0.0</lower><upper>{limits.FINGER_MAX}</upper><velocity>{limits.FINGER_SPEED_MAX}</velocity><effort>{limits.FINGER_FORCE_MAX}</effort></limit>
        <dynamics><damping>0.0</damping></dynamics>
      </axis>
    </joint>
"""
    return _sdf("panda_hand", body,
                "Franka Hand: two prismatic fingers, 0-0.04 m each; TCP frame "
                "panda_tcp 0.1034 m from the hand frame.")


TABLE_TOP = (1.4, 1.4, 0.04)
TABLE_CENTRE = (0.45, 0.0)


def table() -> str:
    x, y = TABLE_CENTRE
    sx, sy, sz = TABLE_TOP
    body = f"""    <link name="table_top">
{_inertial(20.0, (x, y, -sz / 2), _box_inertia(20.0, TABLE_TOP))}{_box("top", (x, y, -sz / 2), TABLE_TOP, WOOD)}"""
    for i, (lx, ly) in enumerate(((1, 1), (1, -1), (-1, 1), (-1, -1))):
        body += _box(f"leg{i}", (x + lx * (sx / 2 - 0.05), y + ly * (sy / 2 - 0.05), -0.4),
                     (0.05, 0.05, 0.72), WOOD, collision=False)
    body += "    </link>\n"
    return _sdf("table", body, "A wooden table; its top surface is the plane z = 0 of its frame.")


# Box with a hinged lid (Open, Close). Base frame: centre of the bottom face,
# x toward the robot's far side (hinge side), y along the long side.
BOX_BASE = (0.20, 0.30, 0.13)
LID = (0.225, 0.30, 0.02)          # overhangs the front by 2.5 cm: the lip
HINGE = (0.10, 0.0, 0.13)          # back top edge
# The lid's stay (a strap or stop) holds it open at this angle [rad], past its
# tipping angle; the hinge's damping and friction are the scenario's
# (drake_skill/station/scenarios), applied by the station builder.
LID_STAY = 1.9


def box() -> str:
    bx, by, bz = BOX_BASE
    lx, ly, lz = LID
    body = f"""    <link name="box_base">
{_inertial(2.0, (0, 0, bz / 2), _box_inertia(2.0, BOX_BASE))}{_box("base", (0, 0, bz / 2), BOX_BASE, BLUE)}    </link>
    <link name="box_lid">
      <pose relative_to="lid_hinge"/>
{_inertial(0.3, (-lx / 2, 0, lz / 2), _box_inertia(0.3, LID))}{_box("lid", (-lx / 2, 0, lz / 2), LID, BLUE)}    </link>
    <joint name="lid_hinge" type="revolute">
      <pose relative_to="box_base">{_pose(HINGE)}</pose>
      <parent>box_base</parent>
      <child>box_lid</child>
      <axis>
        <xyz>0 1 0</xyz>
        <limit><lower>0.0</lower><upper>{LID_STAY}</upper><effort>0</effort></limit>
      </axis>
    </joint>
"""
    return _sdf("box", body,
                "A solid blue box (0.20 x 0.30 x 0.15 m) whose lid is hinged along "
                "its back top edge; the lid overhangs the front by 2.5 cm (a lip to push). "
                "Joint angle 0 = closed, positive = open.")


# Drawer unit (Draw). Cabinet frame: centre of the bottom face; the drawer
# slides out along -x (toward the robot).
CABINET = (0.30, 0.34, 0.22)
DRAWER = (0.28, 0.30, 0.12)
DRAWER_Z = 0.08                    # drawer bottom above the cabinet bottom
HANDLE_STANDOFF = 0.05
HANDLE_LENGTH = 0.14
HANDLE_RADIUS = 0.008


def drawer() -> str:
    cx, cy, cz = CABINET
    dx, dy, dz = DRAWER
    front = -dx / 2 - 0.005
    drawer_geometry = (_box("drawer_body", (0, 0, dz / 2), DRAWER, BLUE)
                       + _box("drawer_front", (front, 0, dz / 2), (0.01, dy + 0.02, dz + 0.02), BLUE))
    body = f"""    <link name="cabinet">
{_inertial(8.0, (0, 0, cz / 2), _box_inertia(8.0, CABINET))}{_box("cabinet", (0, 0, cz / 2), CABINET, BLUE)}    </link>
    <link name="drawer">
      <pose relative_to="drawer_slide"/>
{_inertial(1.0, (0, 0, dz / 2), _box_inertia(1.0, DRAWER))}{drawer_geometry}"""
    for i, s in enumerate((1, -1)):
        body += _box(f"standoff{i}", (front - HANDLE_STANDOFF / 2, s * (HANDLE_LENGTH / 2 - 0.01), dz / 2),
                     (HANDLE_STANDOFF, 0.012, 0.012), BLUE)
    body += _cylinder("handle", (front - HANDLE_STANDOFF, 0, dz / 2), HANDLE_RADIUS, HANDLE_LENGTH,
                      BLUE, rpy=(PI / 2, 0, 0))
    body += f"""    </link>
    <joint name="drawer_slide" type="prismatic">
      <pose relative_to="cabinet">{_pose((-(cx - dx) / 2, 0, DRAWER_Z))}</pose>
      <parent>cabinet</parent>
      <child>drawer</child>
      <axis>
        <xyz>-1 0 0</xyz>
        <limit><lower>0.0</lower><upper>0.22</upper><effort>0</effort></limit>
      </axis>
    </joint>
"""
    return _sdf("drawer", body,
                "A blue drawer unit: cabinet 0.30 x 0.34 x 0.22 m, drawer sliding "
                "out along -x (0 = shut), a bar handle 5 cm proud of its front.")


# Box with a sliding lid (the fourth skill, Slide: drake_skill/skills/slide.yaml).
# Base frame: centre of the bottom face; the lid slides out along +y (sideways,
# away from the camera) and carries a ridge near its -y edge to push against.
SLIDER_BASE = (0.20, 0.30, 0.10)
SLIDER_LID = (0.20, 0.30, 0.015)
SLIDER_RIDGE = (0.12, 0.02, 0.03)    # across the lid, centred 0.12 m from its middle toward -y
SLIDER_RIDGE_Y = -0.12
SLIDER_TRAVEL = 0.20
GREEN = "0.15 0.60 0.20 1"


def slider() -> str:
    bx, by, bz = SLIDER_BASE
    lx, ly, lz = SLIDER_LID
    rx, ry, rz = SLIDER_RIDGE
    base_box = _box("base", (0, 0, bz / 2), SLIDER_BASE, GREEN)
    lid_geometry = (_box("lid", (0, 0, lz / 2), SLIDER_LID, GREEN)
                    + _box("ridge", (0, SLIDER_RIDGE_Y, lz + rz / 2), SLIDER_RIDGE, GREEN))
    body = f"""    <link name="slider_base">
{_inertial(2.0, (0, 0, bz / 2), _box_inertia(2.0, SLIDER_BASE))}{base_box}    </link>
    <link name="slider_lid">
      <pose relative_to="lid_slide"/>
{_inertial(0.4, (0, 0, lz / 2), _box_inertia(0.4, SLIDER_LID))}{lid_geometry}    </link>
    <joint name="lid_slide" type="prismatic">
      <pose relative_to="slider_base">{_pose((0.0, 0.0, bz))}</pose>
      <parent>slider_base</parent>
      <child>slider_lid</child>
      <axis>
        <xyz>0 1 0</xyz>
        <limit><lower>0.0</lower><upper>{SLIDER_TRAVEL}</upper><effort>0</effort></limit>
      </axis>
    </joint>
"""
    return _sdf("slider", body,
                "A green box (0.20 x 0.30 x 0.10 m) whose 1.5 cm lid slides out along +y "
                "(0 = shut, up to 0.20 m), with a 3 cm ridge across it near its -y edge.")


PACKAGE_XML = """<?xml version="1.0"?>
<package format="2">
  <name>drake_skill_models</name>
  <version>0.1.0</version>
  <description>Models shipped with drake-skill (Panda, table, box, drawer, sliding-lid box).</description>
  <maintainer email="drake-skill@example.invalid">drake-skill</maintainer>
  <license>BSD-3-Clause</license>
</package>
"""


def main() -> None:
    files = {
        "panda_arm.sdf": panda_arm(),
        "panda_hand.sdf": panda_hand(),
        "table.sdf": table(),
        "box.sdf": box(),
        "drawer.sdf": drawer(),
        "slider.sdf": slider(),
        "package.xml": PACKAGE_XML,
    }
    files.update(MESHES)
    models = models_dir()  # the checkout's models/ in an editable install
    (models / "meshes").mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        (models / name).write_text(text)
        print(f"wrote {models / name}")


if __name__ == "__main__":
    main()
