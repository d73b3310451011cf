"""Tests of the shipped robot and cell models (models/)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from pydrake.geometry import Role
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.systems.framework import DiagramBuilder

from rtcohand_drake.cell import robot_files as model_files
from rtcohand_drake.cell.faces import (
    COLOUR_RGBA, FACE_DOTS, FACES, WORKPIECE_SIZE, face_key, face_visual_name)

PI = np.pi

# The maker's published Gen3 7-DoF (spherical wrist) joint chain, typed in
# from reference/facts.md, independent of the URDF:
# (joint, parent, child, xyz, rpy, (lower, upper) or None if continuous).
GEN3_CHAIN = (
    ("Actuator1", "base_link", "shoulder_link",
     (0.0, 0.0, 0.15643), (PI, 0.0, 0.0), None),
    ("Actuator2", "shoulder_link", "half_arm_1_link",
     (0.0, 0.005375, -0.12838), (PI / 2, 0.0, 0.0), (-2.41, 2.41)),
    ("Actuator3", "half_arm_1_link", "half_arm_2_link",
     (0.0, -0.21038, -0.006375), (-PI / 2, 0.0, 0.0), None),
    ("Actuator4", "half_arm_2_link", "forearm_link",
     (0.0, 0.006375, -0.21038), (PI / 2, 0.0, 0.0), (-2.66, 2.66)),
    ("Actuator5", "forearm_link", "spherical_wrist_1_link",
     (0.0, -0.20843, -0.006375), (-PI / 2, 0.0, 0.0), None),
    ("Actuator6", "spherical_wrist_1_link", "spherical_wrist_2_link",
     (0.0, 0.00017505, -0.10593), (PI / 2, 0.0, 0.0), (-2.23, 2.23)),
    ("Actuator7", "spherical_wrist_2_link", "bracelet_link",
     (0.0, -0.10593, -0.00017505), (-PI / 2, 0.0, 0.0), None),
)
GEN3_END_EFFECTOR = ("EndEffector", "bracelet_link", "end_effector_link",
                     (0.0, 0.0, -0.061525), (PI, 0.0, 0.0))
GEN3_MASS_KG = {
    "base_link": 1.697, "shoulder_link": 1.3773, "half_arm_1_link": 1.1636,
    "half_arm_2_link": 1.1636, "forearm_link": 0.9302,
    "spherical_wrist_1_link": 0.6781, "spherical_wrist_2_link": 0.6781,
    "bracelet_link": 0.5006,
}
GEN3_COM = {
    "base_link": (-0.000648, -0.000166, 0.084487),
    "shoulder_link": (-2.3e-5, -0.010364, -0.07336),
    "half_arm_1_link": (-4.4e-5, -0.09958, -0.013278),
    "half_arm_2_link": (-4.4e-5, -0.006641, -0.117892),
    "forearm_link": (-1.8e-5, -0.075478, -0.015006),
    "spherical_wrist_1_link": (1e-6, -0.009432, -0.063883),
    "spherical_wrist_2_link": (1e-6, -0.045483, -0.00965),
    "bracelet_link": (-0.000281, -0.011402, -0.029798),
}
SPEED_LIMIT_DEG_S = (80, 80, 80, 80, 70, 70, 70)
EFFORT_LIMIT_NM = (39, 39, 39, 39, 9, 9, 9)

ALL_URLS = (
    model_files.GEN3_URL, model_files.GRIPPER_URL, model_files.WORKPIECE_URL,
    model_files.TABLE_URL, model_files.MOLD_URL, model_files.SAFETY_GLASS_URL,
    model_files.INSPECTOR_URL,
)


def _rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rot_y(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _homogeneous(xyz, rpy):
    """URDF origin: fixed-axis roll, pitch, yaw, R = Rz(yaw) Ry(pitch) Rx(roll)."""
    T = np.eye(4)
    T[:3, :3] = _rot_z(rpy[2]) @ _rot_y(rpy[1]) @ _rot_x(rpy[0])
    T[:3, 3] = xyz
    return T


def _published_link_poses(q):
    """Pose of every Gen3 link in base_link, from the published chain."""
    poses = {"base_link": np.eye(4)}
    for (name, parent, child, xyz, rpy, _), qi in zip(GEN3_CHAIN, q):
        joint_rotation = np.eye(4)
        joint_rotation[:3, :3] = _rot_z(qi)
        poses[child] = poses[parent] @ _homogeneous(xyz, rpy) @ joint_rotation
    _, parent, child, xyz, rpy = GEN3_END_EFFECTOR
    poses[child] = poses[parent] @ _homogeneous(xyz, rpy)
    return poses


def _new_plant(time_step=0.0):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step)
    parser = Parser(plant)
    model_files.add_package(parser)
    return builder, plant, scene_graph, parser


@pytest.fixture(scope="module")
def gen3():
    plant = MultibodyPlant(0.0)
    parser = Parser(plant)
    model_files.add_package(parser)
    (instance,) = parser.AddModels(url=model_files.GEN3_URL)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link"))
    plant.Finalize()
    return plant, instance


def test_models_dir_and_package(tmp_path):
    directory = model_files.models_dir()
    assert (directory / "package.xml").is_file()
    plant = MultibodyPlant(0.0)
    parser = Parser(plant)
    model_files.add_package(parser)
    model_files.add_package(parser)  # registering twice is harmless
    assert parser.package_map().GetPath(model_files.PACKAGE_NAME) == str(directory)


def test_gen3_forward_kinematics_matches_published_chain(gen3):
    plant, _ = gen3
    context = plant.CreateDefaultContext()
    rng = np.random.default_rng(20240611)
    world = plant.world_frame()
    for _ in range(20):
        q = np.empty(7)
        for i, (*_, limits) in enumerate(GEN3_CHAIN):
            low, high = limits if limits is not None else (-2 * PI, 2 * PI)
            q[i] = rng.uniform(low, high)
        plant.SetPositions(context, q)
        expected = _published_link_poses(q)
        assert len(expected) == 9
        for link, T in expected.items():
            X = plant.CalcRelativeTransform(context, world, plant.GetFrameByName(link))
            np.testing.assert_allclose(X.translation(), T[:3, 3], rtol=0, atol=1e-6,
                                       err_msg=link)
            np.testing.assert_allclose(X.rotation().matrix(), T[:3, :3], rtol=0,
                                       atol=1e-9, err_msg=link)


def test_gen3_zero_configuration_points_straight_up(gen3):
    plant, _ = gen3
    context = plant.CreateDefaultContext()
    X_WE = plant.CalcRelativeTransform(
        context, plant.world_frame(), plant.GetFrameByName("end_effector_link"))
    # Sum of the chain's vertical offsets: about 1.19 m.
    assert X_WE.translation()[2] == pytest.approx(1.187385, abs=1e-6)
    np.testing.assert_allclose(X_WE.rotation().matrix()[:, 2], [0, 0, 1], atol=1e-9)


def test_gen3_joints_and_limits(gen3):
    plant, instance = gen3
    revolute = []
    for index in plant.GetJointIndices(instance):
        joint = plant.get_joint(index)
        if joint.num_positions() == 1:
            revolute.append(joint)
    assert [j.name() for j in revolute] == [row[0] for row in GEN3_CHAIN]
    for joint, row, speed_deg_s in zip(revolute, GEN3_CHAIN, SPEED_LIMIT_DEG_S):
        _, parent, child, *_, limits = row
        assert joint.type_name() == "revolute"
        assert joint.parent_body().name() == parent
        assert joint.child_body().name() == child
        np.testing.assert_allclose(joint.revolute_axis(), [0, 0, 1])
        if limits is None:
            assert joint.position_lower_limits()[0] == -np.inf
            assert joint.position_upper_limits()[0] == np.inf
        else:
            assert joint.position_lower_limits()[0] == pytest.approx(limits[0])
            assert joint.position_upper_limits()[0] == pytest.approx(limits[1])
        speed = np.deg2rad(speed_deg_s)
        assert joint.velocity_upper_limits()[0] == pytest.approx(speed, rel=1e-9)
        assert joint.velocity_lower_limits()[0] == pytest.approx(-speed, rel=1e-9)
    weld = plant.GetJointByName("EndEffector", instance)
    assert weld.type_name() == "weld"
    assert weld.child_body().name() == "end_effector_link"
    actuators = [plant.get_joint_actuator(i) for i in plant.GetJointActuatorIndices(instance)]
    assert [a.joint().name() for a in actuators] == [row[0] for row in GEN3_CHAIN]
    np.testing.assert_allclose([a.effort_limit() for a in actuators], EFFORT_LIMIT_NM)


def test_gen3_masses_and_centres_of_mass(gen3):
    plant, instance = gen3
    context = plant.CreateDefaultContext()
    for link, mass in GEN3_MASS_KG.items():
        body = plant.GetBodyByName(link, instance)
        assert body.default_mass() == pytest.approx(mass, rel=1e-9), link
        spatial_inertia = body.CalcSpatialInertiaInBodyFrame(context)
        np.testing.assert_allclose(spatial_inertia.get_com(), GEN3_COM[link],
                                   atol=1e-9, err_msg=link)
        assert spatial_inertia.IsPhysicallyValid(), link
    assert sum(GEN3_MASS_KG.values()) == pytest.approx(
        plant.CalcTotalMass(context, [instance]), rel=1e-9)


def test_model_files_name_no_network_resources():
    directory = model_files.models_dir()
    files = [p for p in directory.rglob("*")
             if p.suffix in (".urdf", ".sdf", ".xml")]
    assert len(files) >= 8
    for path in files:
        text = path.read_text()
        assert "package://drake" not in text, path
        assert "http" not in text, path


def test_models_parse_with_no_network(tmp_path):
    # Drake 1.51 builds every Parser's default package map with the remote
    # `drake_models` package; DRAKE_ALLOW_NETWORK=none (or any value leaving
    # out `package_map`) makes Parser construction itself throw. So the
    # child process allows only `package_map`, drops the remote packages,
    # points the download cache at an empty directory and routes any
    # download to a closed port: a model needing the network cannot load.
    script = textwrap.dedent(f"""
        from pydrake.multibody.parsing import Parser
        from pydrake.multibody.plant import MultibodyPlant
        from rtcohand_drake.cell import robot_files as model_files
        plant = MultibodyPlant(0.0)
        parser = Parser(plant)
        parser.package_map().Remove("drake_models")
        model_files.add_package(parser)
        for url in {list(ALL_URLS)!r}:
            parser.AddModels(url=url)
        plant.Finalize()
        print("parsed", plant.num_model_instances())
        # Control: the same process cannot fetch anything.
        other = Parser(MultibodyPlant(0.0))
        try:
            other.package_map().GetPath("drake_models")
        except RuntimeError:
            print("offline confirmed")
    """)
    env = dict(os.environ)
    env.update(DRAKE_ALLOW_NETWORK="package_map", XDG_CACHE_HOME=str(tmp_path),
               HOME=str(tmp_path), http_proxy="http://127.0.0.1:9",
               https_proxy="http://127.0.0.1:9", HTTP_PROXY="http://127.0.0.1:9",
               HTTPS_PROXY="http://127.0.0.1:9", no_proxy="", NO_PROXY="")
    result = subprocess.run([sys.executable, "-c", script], env=env,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "parsed 9" in result.stdout  # world, default and 7 models
    assert "offline confirmed" in result.stdout


@pytest.fixture(scope="module")
def arm_with_tool():
    builder, plant, scene_graph, parser = _new_plant()
    parser.AddModels(url=model_files.GEN3_URL)
    (gripper,) = parser.AddModels(url=model_files.GRIPPER_URL)
    (workpiece,) = parser.AddModels(url=model_files.WORKPIECE_URL)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link"))
    plant.WeldFrames(plant.GetFrameByName("end_effector_link"),
                     plant.GetFrameByName("robotiq_base_link"))
    # Fingers close along the gripper's x on the part's 0.05 m (z) side.
    plant.WeldFrames(plant.GetFrameByName("grasp_frame"),
                     plant.GetFrameByName("workpiece"),
                     RigidTransform(RollPitchYaw(0, PI / 2, 0), [0, 0, 0]))
    plant.Finalize()
    diagram = builder.Build()
    return diagram, plant, scene_graph, gripper, workpiece


def test_gripper(arm_with_tool):
    diagram, plant, scene_graph, gripper, _ = arm_with_tool
    context = plant.CreateDefaultContext()
    assert plant.num_positions() == 7  # the gripper adds no degree of freedom
    assert plant.CalcTotalMass(context, [gripper]) == pytest.approx(0.9, abs=0.05)
    X_EG = plant.CalcRelativeTransform(context, plant.GetFrameByName("end_effector_link"),
                                       plant.GetFrameByName("grasp_frame"))
    np.testing.assert_allclose(X_EG.translation(), [0, 0, 0.143], atol=1e-12)
    np.testing.assert_allclose(X_EG.rotation().matrix(), np.eye(3), atol=1e-12)
    # Coupling to fingertip about 0.16 m; pads 0.05 m apart.
    inspector = scene_graph.model_inspector()
    tip_z, pad_x = [], []
    for name in ("left_finger", "right_finger"):
        body = plant.GetBodyByName(name, gripper)
        X_BF = plant.CalcRelativeTransform(context, plant.GetFrameByName("robotiq_base_link"),
                                           body.body_frame())
        for geometry_id in inspector.GetGeometries(
                plant.GetBodyFrameIdOrThrow(body.index()), Role.kProximity):
            box = inspector.GetShape(geometry_id)
            X_FG = inspector.GetPoseInFrame(geometry_id)
            centre = (X_BF @ X_FG).translation()
            tip_z.append(centre[2] + box.height() / 2)
            if inspector.GetName(geometry_id).endswith("pad"):
                pad_x.append(centre[0])
                pad_x_inner = abs(centre[0]) - box.width() / 2
                assert pad_x_inner == pytest.approx(0.025, abs=1e-9)
    assert max(tip_z) == pytest.approx(0.16, abs=1e-9)
    assert sorted(np.sign(pad_x)) == [-1, 1]


def test_held_workpiece_does_not_touch_the_arm(arm_with_tool):
    diagram, plant, scene_graph, _, _ = arm_with_tool
    context = diagram.CreateDefaultContext()
    query = scene_graph.get_query_output_port().Eval(
        scene_graph.GetMyContextFromRoot(context))
    assert query.ComputePointPairPenetration() == []


def _rgba_of(inspector, geometry_id):
    diffuse = inspector.GetIllustrationProperties(geometry_id).GetProperty(
        "phong", "diffuse")
    return np.array([diffuse.r(), diffuse.g(), diffuse.b(), diffuse.a()])


def test_workpiece():
    builder, plant, scene_graph, parser = _new_plant()
    (instance,) = parser.AddModels(url=model_files.WORKPIECE_URL)
    plant.Finalize()
    body = plant.GetBodyByName("workpiece", instance)
    mass = body.default_mass()
    assert 0.3 < mass < 4.0  # aluminium part, within the 4 kg payload
    sx, sy, sz = WORKPIECE_SIZE
    inertia = body.default_rotational_inertia()
    expected = mass / 12 * np.array([sy**2 + sz**2, sx**2 + sz**2, sx**2 + sy**2])
    np.testing.assert_allclose(inertia.CopyToFullMatrix3(), np.diag(expected), rtol=1e-6)
    np.testing.assert_allclose(body.default_com(), 0, atol=1e-12)

    inspector = scene_graph.model_inspector()
    frame_id = plant.GetBodyFrameIdOrThrow(body.index())
    (collision,) = inspector.GetGeometries(frame_id, Role.kProximity)
    np.testing.assert_allclose(
        [inspector.GetShape(collision).width(), inspector.GetShape(collision).depth(),
         inspector.GetShape(collision).height()], WORKPIECE_SIZE)
    visuals = {inspector.GetName(g).split("::")[-1]: g
               for g in inspector.GetGeometries(frame_id, Role.kIllustration)}
    colours = []
    for name, normal, colour in FACES:
        plate = visuals[face_visual_name(name)]
        rgba = _rgba_of(inspector, plate)
        np.testing.assert_allclose(rgba, COLOUR_RGBA[colour])
        colours.append(tuple(rgba))
        # The plate lies on its face: outer side flush with the box.
        centre = inspector.GetPoseInFrame(plate).translation()
        axis = int(np.argmax(np.abs(normal)))
        shape = inspector.GetShape(plate)
        thickness = (shape.width(), shape.depth(), shape.height())[axis]
        assert np.sign(centre[axis]) == normal[axis]
        assert abs(centre[axis]) + thickness / 2 == pytest.approx(WORKPIECE_SIZE[axis] / 2)
        dots = [v for k, v in visuals.items() if k.startswith(f"face_{face_key(name)}_dot")]
        assert len(dots) == FACE_DOTS[name]
        for dot in dots:
            assert np.dot(inspector.GetPoseInFrame(dot).translation(), normal) > \
                WORKPIECE_SIZE[axis] / 2
    assert len(set(colours)) == 6
    assert sorted(FACE_DOTS.values()) == [1, 2, 3, 4, 5, 6]
    assert [n for n, _, _ in FACES] == ["+x", "-x", "+y", "-y", "+z", "-z"]


def test_workpiece_sdf_is_current():
    sys.path.insert(0, str(model_files.models_dir() / "workpiece"))
    try:
        import make_workpiece_sdf
    finally:
        sys.path.pop(0)
    shipped = (model_files.models_dir() / "workpiece" / "workpiece.sdf").read_text()
    assert make_workpiece_sdf.make_sdf() == shipped, (
        "run models/workpiece/make_workpiece_sdf.py")


def test_cell_models():
    builder, plant, scene_graph, parser = _new_plant()
    instances = {}
    for url in (model_files.TABLE_URL, model_files.MOLD_URL,
                model_files.SAFETY_GLASS_URL, model_files.INSPECTOR_URL,
                model_files.WORKPIECE_URL):
        (instance,) = parser.AddModels(url=url)
        instances[plant.GetModelInstanceName(instance)] = instance
    assert set(instances) == {"table", "mold", "safety_glass", "inspector", "workpiece"}
    for name in ("table", "mold", "safety_glass", "inspector"):
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(name, instances[name]))
    # Workpiece standing upright in the mold cavity (its y up), 1 mm above the floor.
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("workpiece"),
                     RigidTransform(RollPitchYaw(np.pi / 2, 0, 0), [0.0, 0.0, 0.051]))
    # (Everything is welded at the origin; only workpiece-mold pairs are queried.)
    plant.Finalize()
    inspector = scene_graph.model_inspector()

    def geometries(name, role):
        body = plant.GetBodyByName(name, instances[name])
        return inspector.GetGeometries(plant.GetBodyFrameIdOrThrow(body.index()), role)

    # Inspector: visual only, eye frame 1.6 m above its origin.
    assert geometries("inspector", Role.kProximity) == []
    assert len(geometries("inspector", Role.kIllustration)) > 5
    context = plant.CreateDefaultContext()
    X_OE = plant.CalcRelativeTransform(context, plant.GetFrameByName("inspector"),
                                       plant.GetFrameByName("eye"))
    np.testing.assert_allclose(X_OE.translation(), [0, 0, 1.6])

    # Safety glass: transparent pane 1.2 x 1.0 x 0.01 m, bottom edge at origin.
    (panel,) = geometries("safety_glass", Role.kProximity)
    shape = inspector.GetShape(panel)
    np.testing.assert_allclose([shape.width(), shape.depth(), shape.height()], [1.2, 0.01, 1.0])
    np.testing.assert_allclose(inspector.GetPoseInFrame(panel).translation(), [0, 0, 0.5])
    alphas = [_rgba_of(inspector, g)[3] for g in geometries("safety_glass", Role.kIllustration)]
    assert min(alphas) == pytest.approx(0.25)

    # Table: top surface at z = 0.
    top_z = []
    for g in geometries("table", Role.kProximity):
        box = inspector.GetShape(g)
        top_z.append(inspector.GetPoseInFrame(g).translation()[2] + box.height() / 2)
    assert max(top_z) == pytest.approx(0.0, abs=1e-12)

    # Mold: the workpiece sits in the cavity with 8 mm clearance all round.
    diagram = builder.Build()
    root = diagram.CreateDefaultContext()
    query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(root))
    (part,) = geometries("workpiece", Role.kProximity)
    distances = {}
    for g in geometries("mold", Role.kProximity):
        distances[inspector.GetName(g).split("::")[-1]] = \
            query.ComputeSignedDistancePairClosestPoints(part, g).distance
    assert distances["floor"] == pytest.approx(0.001, abs=1e-9)
    for wall in ("wall_px", "wall_nx", "wall_py", "wall_ny"):
        assert distances[wall] == pytest.approx(0.008, abs=1e-9), wall
    # The cavity is 0.04 m deep; the part's upper 0.06 m stand above the rim for the gripper.
    rim = max(inspector.GetPoseInFrame(g).translation()[2] + inspector.GetShape(g).height() / 2
              for g in geometries("mold", Role.kProximity))
    assert rim == pytest.approx(0.04)
