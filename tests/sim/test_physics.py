"""The MuJoCo physics engine: model, contacts and their ground truth, controller, log profile."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from cli.main import cli
from wholearm_tools.contacts import detect_contacts
from wholearm_tools.errors import InputError
from wholearm_tools.geometry import (
    Arc2D,
    Circle2D,
    Line2D,
    Plane,
    Sphere,
    Surface,
    Torus,
)
from wholearm_tools.logs import read_run, write_run
from wholearm_tools.robot.model import RobotModel
from wholearm_tools.sim.collision import Collider
from wholearm_tools.sim.mjcf import PhysicsModelError, SceneOptions, build_scene
from wholearm_tools.sim.occupancy import SweptGrid
from wholearm_tools.sim.physics import Physics, simulate_physics
from wholearm_tools.sim.simulator import simulate
from wholearm_tools.sim.strategies import Strategy

from .conftest import two_link


class Scripted(Strategy):
    """Targets from a list, then nothing (the arm holds its last reference)."""

    name = "scripted"

    def __init__(self, robot, collider, grid, targets, **kwargs) -> None:
        super().__init__(robot, collider, grid, free_target=False, **kwargs)
        self.targets = [np.asarray(t, dtype=float) for t in targets]

    def next_target(self, q):
        return self.targets.pop(0) if self.targets else None


def run_scripted(robot, obstacles, targets, home, physics=None, duration=3.0, seed=1,
                 rate=500.0):
    strategy = Scripted(robot, Collider(robot, obstacles), SweptGrid(robot), targets)
    return simulate_physics(robot, obstacles, strategy=strategy, duration=duration, seed=seed,
                            home=home, physics=physics, rate=rate)


def wall(x: float) -> list:
    """A 2-D wall at ``x``, free on the side of the base."""
    return [Surface(Line2D([x, 0.0], [0.0, 1.0]), free_side=1, surface_id=0)]


def spatial_arm() -> RobotModel:
    """Roll, pitch, pitch with a tilted origin (rpy), so the scene's frames are not trivial."""
    return RobotModel.from_spec({
        "joints": [
            {"name": "yaw", "origin": [0, 0, 0.05], "axis": [0, 0, 1], "radius": 0.04,
             "effort": 20.0, "velocity": 1.2},
            {"name": "pitch", "origin": [0, 0, 0.1], "rpy": [0.3, 0.0, 0.2], "axis": [0, 1, 0],
             "radius": 0.03, "limits": [-2.0, 2.0], "effort": 15.0, "velocity": 1.2},
            {"name": "elbow", "origin": [0.3, 0, 0], "axis": [0, 1, 0], "radius": 0.02,
             "limits": [-2.5, 2.5], "effort": 8.0, "velocity": 1.2},
        ],
        "tip": {"offset": [0.25, 0.0, 0.0], "radius": 0.025},
    }, name="spatial3")


def options(robot: RobotModel, max_deviation: float = 3e-4) -> SceneOptions:
    n = robot.dof
    return SceneOptions(timestep=1e-3, gravity=False, friction=0.4, solref=(0.005, 0.7),
                        density=1000.0, armature=(0.01,) * n, frictionloss=(0.0,) * n,
                        damping=(0.1,) * n, max_deviation=max_deviation)


@pytest.mark.parametrize("robot", [two_link(), spatial_arm()], ids=["planar", "spatial"])
def test_mjcf_kinematics_match_the_robot_model(robot: RobotModel) -> None:
    import mujoco

    floor = [Surface(Plane([0, 0, -0.5], [0, 0, 1]), free_side=1)] if robot.dim == 3 \
        else wall(0.9)
    scene = build_scene(robot, floor, options(robot))
    model = mujoco.MjModel.from_xml_string(scene.xml)
    data = mujoco.MjData(model)
    bodies = [model.body(f"link{i}").id for i in range(robot.dof)]
    rng = np.random.default_rng(3)
    for q in rng.uniform(robot.lower, robot.upper, size=(10, robot.dof)):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        got = np.vstack([data.xpos[bodies], data.site_xpos[model.site("tip").id]])
        np.testing.assert_allclose(got, robot.joint_positions(q), atol=1e-12)
    # one hinge per joint with the robot's limits, one motor limited to each effort limit
    np.testing.assert_allclose(model.jnt_range, np.stack([robot.lower, robot.upper], 1))
    np.testing.assert_allclose(model.actuator_ctrlrange[:, 1], robot.effort_limits)


def test_tip_pressed_on_a_wall_is_a_stopping_tip_event_on_the_surface() -> None:
    robot = two_link()
    res = run_scripted(robot, wall(0.55), [(-0.4, 0.0)], home=(1.0, 0.0))
    truth = res.truth
    stopped = np.flatnonzero(truth.contact_stopped)
    assert stopped.size == 1
    i = int(stopped[0])
    assert truth.contact_link[i] == 1
    assert truth.contact_kind[i] == "tip"
    assert truth.contact_surface[i] == 0
    assert abs(truth.contact_point[i, 0] - 0.55) < 1e-3  # on the wall
    assert truth.contact_point[i, 2] == 0.0  # planar
    assert truth.contact_force[i] > 1.0
    assert truth.contact_t_end[i] > truth.contact_t[i]
    # the settled configuration puts the tip sphere against the wall
    tip = robot.tip_position(truth.contact_q[i])
    assert abs(tip[0] + robot.tip_radius - 0.55) < 2e-3
    # the move stopped against it: the supervisor saw the arm short of its target
    (move,) = res.moves
    assert move.contacts == (i,)
    assert move.t_stop < move.t_retreat < move.t_end


def test_a_run_logged_at_50_hz_is_the_500_hz_run_decimated() -> None:
    """The drive's control loop runs at the physics rate whatever the log rate (its velocity
    estimate spans 10 ms, not five log periods): logging at 50 Hz only drops samples, and the
    arm presses the wall the same way, touching it the same times."""
    robot = two_link()
    runs = {rate: run_scripted(robot, wall(0.55), [(-0.4, 0.0)], home=(1.0, 0.0), rate=rate)
            for rate in (500.0, 50.0)}
    fast, slow = runs[500.0].run.log, runs[50.0].run.log
    np.testing.assert_array_equal(fast.q[::10], slow.q)
    np.testing.assert_array_equal(fast.tau_cmd[::10], slow.tau_cmd)
    np.testing.assert_array_equal(runs[500.0].truth.contact_t, runs[50.0].truth.contact_t)


def test_a_run_logged_by_a_rigs_clock_is_the_same_run_sampled_when_stamped() -> None:
    """A rig's logger ticks irregularly and loses samples: at 50 Hz with intervals varying by
    10 % and 5 % of the samples lost, every logged sample is the 1 kHz run's sample at its own
    stamp (the logging does not touch the physics), the intervals vary as asked, and the log
    velocity is the backward difference over the samples' own times."""
    robot = two_link()
    clock = Physics(log_jitter=0.1, log_drop=0.05)
    fine = run_scripted(robot, wall(0.55), [(-0.4, 0.0)], home=(1.0, 0.0), rate=1000.0,
                        duration=6.0).run.log
    res = run_scripted(robot, wall(0.55), [(-0.4, 0.0)], home=(1.0, 0.0), rate=50.0,
                       duration=6.0, physics=clock)
    log = res.run.log
    at = np.rint(log.t * 1000.0).astype(int)
    np.testing.assert_allclose(log.t * 1000.0, at, atol=1e-6)  # on the physics steps
    np.testing.assert_array_equal(fine.q[at], log.q)
    np.testing.assert_array_equal(fine.tau_cmd[at], log.tau_cmd)
    steps = np.diff(log.t)
    single = steps[steps < 0.03]  # intervals with no sample lost between
    assert 0.07 < single.std() / 0.02 < 0.13
    assert 0.02 < 1.0 - len(log.t) / 300.0 < 0.09
    assert np.all(steps > 0)
    w = 5
    span = (log.t[w:] - log.t[:-w])[:, None]
    np.testing.assert_allclose(log.qd[w:], (log.q[w:] - log.q[:-w]) / span)
    plain = run_scripted(robot, wall(0.55), [(-0.4, 0.0)], home=(1.0, 0.0), rate=50.0,
                         duration=6.0)
    np.testing.assert_array_equal(res.truth.contact_t, plain.truth.contact_t)


def test_motor_side_encoders_read_the_transmissions_deflection() -> None:
    """With a compliant transmission the encoders read the link's position plus the
    deflection under the drive's torque: pressing a wall, the logged position of the blocked
    shoulder leads the link's by compliance x torque / effort (1 mrad here, a hundred times
    the encoder's noise); with a rigid one they agree to the noise."""
    robot = two_link()
    effort = robot.effort_limits[0]
    for compliance in (0.0, 0.002):
        res = run_scripted(robot, wall(0.55), [(-0.4, 0.0)], home=(1.0, 0.0),
                           physics=Physics(joint_compliance=compliance))
        log = res.run.log
        pressing = np.flatnonzero(np.abs(log.tau_cmd[:-1, 0]) > 0.5 * effort) + 1
        assert pressing.size > 50
        seen = log.q[pressing, 0] - res.q_true[pressing, 0]
        deflection = compliance * log.tau_cmd[pressing - 1, 0] / effort
        np.testing.assert_allclose(seen, deflection, atol=1e-4)
        if compliance:
            assert np.median(np.abs(deflection)) > 5e-4


def test_contacts_told_the_compliance_settle_at_the_links_angles(tmp_path) -> None:
    """Told the drives' compliance (a datasheet's stiffness), the detector places a contact
    at the links' angles, not the motor side's; its signals, and so the contact found, stay
    the same.  Read from the log, the compliance is the one given, checked per joint."""
    robot = two_link()
    res = run_scripted(robot, wall(0.55), [(-0.4, 0.0)], home=(1.0, 0.0),
                       physics=Physics(joint_compliance=0.002))
    path = tmp_path / "compliant.mcap"
    write_run(path, res.run)
    read = {c: read_run(path, joint_compliance=c) for c in (None, 0.002)}
    assert np.array_equal(read[0.002].robot.joint_compliance, [0.002, 0.002])
    found = {c: detect_contacts(run.log, run.robot) for c, run in read.items()}
    assert len(found[None]) == len(found[0.002]) >= 1
    assert np.array_equal(found[None].index, found[0.002].index)
    assert np.array_equal(found[None].link, found[0.002].link)
    true_q = res.q_true[found[None].index]
    assert np.abs(found[None].q - true_q).max() > 5e-4      # the deflection, read as angle
    assert np.abs(found[0.002].q - true_q).max() < 2e-4     # the links' angles
    with pytest.raises(InputError, match=r"compliant\.mcap: .*one joint compliance or 2"):
        read_run(path, joint_compliance=(0.001, 0.001, 0.001))


def test_motor_side_encoders_read_the_play_closed_on_the_pushed_side(tmp_path) -> None:
    """With play in the transmissions the encoders lead the link by half the play in the
    direction the drive pushes: pressing a wall, the blocked shoulder is read 1 mrad (a
    hundred times the encoder's noise) beyond its link.  Told the play, the detector places
    the contact at the links' angles; the contact found stays the same."""
    robot = two_link()
    res = run_scripted(robot, wall(0.55), [(-0.4, 0.0)], home=(1.0, 0.0),
                       physics=Physics(joint_backlash=0.002))
    log = res.run.log
    effort = robot.effort_limits[0]
    pressing = np.flatnonzero(np.abs(log.tau_cmd[:-1, 0]) > 0.5 * effort) + 1
    assert pressing.size > 50
    seen = log.q[pressing, 0] - res.q_true[pressing, 0]
    np.testing.assert_allclose(seen, 0.001 * np.sign(log.tau_cmd[pressing - 1, 0]), atol=1e-4)
    path = tmp_path / "play.mcap"
    write_run(path, res.run)
    read = {b: read_run(path, joint_backlash=b) for b in (None, 0.002)}
    found = {b: detect_contacts(run.log, run.robot) for b, run in read.items()}
    assert len(found[None]) == len(found[0.002]) >= 1
    assert np.array_equal(found[None].index, found[0.002].index)
    true_q = res.q_true[found[None].index]
    assert np.abs(found[None].q - true_q).max() > 8e-4      # the play, read as angle
    assert np.abs(found[0.002].q - true_q).max() < 2e-4     # the links' angles


def pushes_across_a_wall() -> list[tuple[float, float]]:
    """Reach toward the wall, then through it, at heights and elbow bends that load the two
    joints in different proportions."""
    targets = []
    for q1 in np.linspace(-0.6, 0.6, 7):
        for bend in (-0.9, 0.9):
            targets += [(q1 + 0.1 * np.sign(bend), 0.2 * bend), (q1 + np.copysign(1.0, q1), bend)]
    return targets


def test_the_drives_compliance_is_learned_from_the_wall_the_arm_pressed() -> None:
    """Pressed in poses that load the joints differently, one wall is read at depths that
    differ by the deflections.  Learned from the map, the compliance comes within 0.3 mrad of
    the 2 mrad simulated, and the wall, 0.8 mm off at the readings, comes back within 0.2 mm;
    a stiff arm learns next to none."""
    from wholearm_tools.calibration import estimate_drives
    from wholearm_tools.pipeline import reconstruct

    robot = two_link()
    on_wall = np.array([[0.55, -0.3], [0.55, 0.0], [0.55, 0.3]])
    for compliance in (0.002, 0.0):
        res = run_scripted(robot, wall(0.55), pushes_across_a_wall(), home=(1.0, 0.0),
                           physics=Physics(joint_compliance=compliance), duration=40.0)
        read = reconstruct(res.run, B=0.02, workers=1)
        learned = estimate_drives(read)
        assert learned.readings >= 6
        np.testing.assert_allclose(learned.compliance, compliance, atol=3e-4)
        if not compliance:
            continue
        rec = reconstruct(res.run, B=0.02, workers=1, learn_compliance=True)
        np.testing.assert_allclose(rec.surface_map.meta["joint_compliance"], compliance,
                                   atol=3e-4)
        # a fixed point: the map made under the learned compliance tells the same compliance
        np.testing.assert_allclose(estimate_drives(rec).compliance,
                                   rec.surface_map.meta["joint_compliance"], atol=1e-4)
        off = [np.abs(r.surface_map.primitives[0].primitive.signed_distance(on_wall)).max()
               for r in (read, rec)]
        assert off[0] > 5e-4     # read at the drives' angles
        assert off[1] < 2e-4     # at the links'
        assert "compliance learned from" in rec.messages[-1]


def test_friction_makes_the_tip_slide_less() -> None:
    robot = two_link()
    slides = []
    for mu in (0.0, 0.6):
        res = run_scripted(robot, wall(0.55), [(-0.4, 0.0)], home=(1.0, 0.0),
                           physics=Physics(friction=mu), duration=2.0)
        first = int(np.argmax(res.truth.contact_stopped))
        slides.append(float(res.stats["events"]["slide"][first]))
    assert slides[0] > 0.05  # frictionless: the pushed tip runs along the wall
    assert slides[1] < 0.2 * slides[0]


def test_joint_friction_leaves_a_residual_torque_at_rest() -> None:
    robot = two_link()
    residual = []
    for fraction in (0.0, 0.05):
        res = run_scripted(robot, wall(2.0), [(1.0, 0.0)], home=(1.6, 0.0),
                           physics=Physics(joint_friction=fraction))
        log = res.run.log
        assert res.truth.n_contacts == 0
        assert np.abs(log.q[-1] - [1.0, 0.0]).max() < 0.03  # reached and at rest
        residual.append(float(np.abs(log.tau_cmd[log.t > 2.5, 0]).mean()))
    friction = 0.05 * robot.effort_limits[0]
    assert residual[1] > 0.1 * friction
    assert residual[1] > 10 * residual[0]


def test_gravity_is_compensated_and_shows_in_the_commanded_torque() -> None:
    robot = spatial_arm()
    floor = [Surface(Plane([0, 0, -0.6], [0, 0, 1]), free_side=1)]
    home = (0.0, -0.3, 0.6)
    torques = []
    for gravity in (False, True):
        res = run_scripted(robot, floor, [], home=home, physics=Physics(gravity=gravity),
                           duration=1.0)
        log = res.run.log
        assert np.abs(log.q[-1] - home).max() < 0.02  # holds its pose either way
        torques.append(log.tau_cmd[-1])
    assert abs(torques[1][1]) > 1.0  # the pitch joint carries the arm's weight
    assert abs(torques[0][1]) < 0.2


def test_same_topics_and_profile_as_the_kinematic_engine(tmp_path: Path, robot, obstacles
                                                         ) -> None:
    from wholearm_tools.logs.inspect import inspect_log

    home = [1.2, -0.8]
    kin = simulate(robot, obstacles, strategy="random", duration=1.0, seed=2, home=home)
    phys = simulate_physics(robot, obstacles, strategy="random", duration=1.0, seed=2,
                            home=home)
    described = {}
    for name, res in (("kinematic", kin), ("physics", phys)):
        path = tmp_path / f"{name}.mcap"
        write_run(path, res.run)
        info = inspect_log(path)
        described[name] = sorted((t["topic"], t["schema"], t["message_encoding"], t["messages"])
                                 for t in info["topics"])
        back = read_run(path)
        assert back.log.n_samples == 501
        assert back.truth is not None
        assert back.truth.meta["engine"] == name
    assert described["kinematic"] == described["physics"]
    np.testing.assert_allclose(phys.run.log.t, kin.run.log.t)


def test_same_seed_gives_a_byte_identical_mcap(tmp_path: Path) -> None:
    paths = [tmp_path / f"{k}.mcap" for k in "abc"]
    for path, seed in zip(paths, ("3", "3", "4"), strict=True):
        res = CliRunner().invoke(cli, ["simulate", "lab_sharp", "--engine", "physics", "-o",
                                       str(path), "--duration", "1.5", "--seed", seed])
        assert res.exit_code == 0, res.output
    assert paths[0].read_bytes() == paths[1].read_bytes()
    assert paths[0].read_bytes() != paths[2].read_bytes()


@pytest.mark.parametrize("engine", ["kinematic", "physics"])
def test_stock_ros2_readers_read_every_channel(tmp_path: Path, engine: str) -> None:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    path = tmp_path / "run.mcap"
    res = CliRunner().invoke(cli, ["simulate", "lab_circle", "--engine", engine, "-o",
                                   str(path), "--duration", "1"])
    assert res.exit_code == 0, res.output
    with AnyReader([path]) as reader:
        topics = {c.topic for c in reader.connections}
        seen = {}
        for conn, _t, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            seen[conn.topic] = msg
    assert topics == {"/joint_states", "/joint_commands", "/robot_description",
                      "/wholearm/ground_truth"}
    assert set(seen) == topics
    assert '"contacts"' in seen["/wholearm/ground_truth"].data
    with path.open("rb") as handle:
        decoded = {ch.topic for _s, ch, _m, _d in
                   make_reader(handle, decoder_factories=[DecoderFactory()])
                   .iter_decoded_messages()}
    assert decoded == topics


def test_a_tiled_pocket_is_within_its_deviation_and_contacts_lie_on_it() -> None:
    robot = two_link()
    pocket = [Surface(Circle2D([0.0, 0.0], 0.55), free_side=-1, surface_id=0)]
    res = run_scripted(robot, pocket, [(1.0, 0.0), (0.0, -1.0)], home=(1.0, -1.5),
                       duration=4.0)
    deviation = res.truth.surfaces[0]["physics_deviation"]
    assert 0.0 < deviation <= Physics().max_deviation
    truth = res.truth
    assert truth.n_contacts >= 2
    radius = np.linalg.norm(truth.contact_point[:, :2], axis=1)
    assert np.abs(radius - 0.55).max() < 1e-3


def test_scene_errors_name_the_obstacle() -> None:
    robot = spatial_arm()
    with pytest.raises(PhysicsModelError, match=r"obstacle 1 .*torus surface is not supported"):
        build_scene(robot, [Surface(Plane([0, 0, -1], [0, 0, 1])),
                            Surface(Torus([1, 0, 0], [0, 0, 1], 0.3, 0.1))], options(robot))
    with pytest.raises(PhysicsModelError, match=r"obstacle 0: the inside of a sphere"):
        build_scene(robot, [Surface(Sphere([0, 0, 0], 2.0), free_side=-1)], options(robot))
    with pytest.raises(PhysicsModelError, match=r"obstacle 0: an arc with an angle range"):
        build_scene(two_link(), [Arc2D([0.5, 0], 0.1, angle_range=(0, 1), free_side=1)],
                    options(two_link()))


def test_physics_parameters_are_checked() -> None:
    with pytest.raises(ValueError, match="physics joint_friction is a fraction"):
        Physics(joint_friction=1.5)
    with pytest.raises(ValueError, match="physics contact_timeconst must be positive"):
        Physics(contact_timeconst=0.0)


def test_cli_physics_options_and_their_errors(tmp_path: Path) -> None:
    out = tmp_path / "run.mcap"
    res = CliRunner().invoke(cli, ["simulate", "lab_circle", "-o", str(out), "--friction",
                                   "0.2"])
    assert res.exit_code != 0
    assert "--friction apply to --engine physics only" in res.output
    assert not out.exists()
    scene = tmp_path / "scene.xml"
    res = CliRunner().invoke(cli, ["simulate", "lab_circle", "--engine", "physics", "-o",
                                   str(out), "--duration", "0.5", "--friction", "0.2",
                                   "--joint-friction", "0.05", "--gravity", "--mjcf",
                                   str(scene)])
    assert res.exit_code == 0, res.output
    physics = read_run(out).truth.meta["physics"]
    assert physics["friction"] == 0.2
    assert physics["joint_friction"] == 0.05
    assert physics["gravity"] is True
    assert scene.read_text().startswith("<mujoco")


def test_scenario_physics_block(tmp_path: Path) -> None:
    from wholearm_tools.errors import ScenarioError
    from wholearm_tools.sim.scenarios import DATASETS, load_scenario

    text = (DATASETS / "lab_circle.yaml").read_text()
    text = text.replace("robot: lab_circle.urdf", f"robot: {DATASETS / 'lab_circle.urdf'}")
    good = tmp_path / "good.yaml"
    good.write_text(text + "physics: {friction: 0.1, contact_dampratio: 0.3}\n")
    sc = load_scenario(good)
    assert sc.physics.friction == 0.1
    assert sc.physics.contact_dampratio == 0.3
    assert sc.physics.joint_friction == Physics().joint_friction
    bad = tmp_path / "bad.yaml"
    bad.write_text(text + "physics: {frictoin: 0.1}\n")
    with pytest.raises(ScenarioError, match=r"bad\.yaml: invalid scenario.*frictoin"):
        load_scenario(bad)


def scene_distances(robot: RobotModel, obstacles: list, points: np.ndarray,
                    farthest: float = 5.0, scene=None) -> np.ndarray:
    """Distance from each point to the nearest environment geom of the (built) scene,
    measured by MuJoCo with a tiny probe sphere (up to ``farthest``), ``(N,)``."""
    import mujoco

    scene = scene or build_scene(robot, obstacles, options(robot))
    probe = ('<body name="probe" mocap="true"><geom name="probe" type="sphere" size="1e-4" '
             'contype="0" conaffinity="0"/></body>')
    xml = scene.xml.replace("</worldbody>", probe + "</worldbody>")
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    env = [model.geom(name).id for name in scene.env_geoms]
    out = []
    for p in points:
        data.mocap_pos[0] = np.r_[p, 0.0][:3]
        mujoco.mj_kinematics(model, data)
        out.append(min(mujoco.mj_geomDistance(model, data, model.geom("probe").id, g,
                                              farthest, None) for g in env) + 1e-4)
    return np.array(out)


@pytest.mark.parametrize("case", ["spatial", "planar"])
def test_scene_geoms_reproduce_the_obstacles_clearance(case: str) -> None:
    """Away from the surfaces (where MuJoCo's distances are exact), each built geom is where
    its obstacle's material is: the scene's distance equals the obstacles' clearance."""
    from wholearm_tools.geometry import CylinderSection, PlanePatch, Segment2D

    rng = np.random.default_rng(5)
    if case == "spatial":
        robot = spatial_arm()
        obstacles = [
            Surface(Plane([0, 0, -0.3], [0, 0, 1]), free_side=1, surface_id=0),
            CylinderSection([0.4, 0.1, -0.3], [0, 0, 1], 0.06, (0.0, 0.5), free_side=1,
                            surface_id=1),
            Surface(Sphere([-0.3, 0.3, 0.2], 0.1), free_side=1, surface_id=2),
            PlanePatch([0.0, -0.5, 0.1], [0, 1, 0], [1, 0, 0], (0.2, 0.15), free_side=-1,
                       thickness=0.05, surface_id=3),
        ]
        points = rng.uniform([-0.7, -0.7, -0.25], [0.7, 0.7, 0.5], size=(300, 3))
    else:
        robot = two_link()
        obstacles = [
            Surface(Line2D([0.0, 0.5], [1.0, 0.0]), free_side=-1, surface_id=0),
            Arc2D([0.3, 0.1], 0.05, free_side=1, surface_id=1),
            Segment2D([-0.3, 0.0], [0.0, 1.0], (-0.2, 0.2), free_side=1, thickness=0.04,
                      surface_id=2),
        ]
        points = rng.uniform([-0.6, -0.6], [0.6, 0.45], size=(300, 2))
    clearance = np.min([obs.clearance(points) for obs in obstacles], axis=0)
    free = clearance > 0.01
    got = scene_distances(robot, obstacles, points[free])
    np.testing.assert_allclose(got, clearance[free], atol=1e-6)


def lip_curve(main, branch, samples: int = 360) -> np.ndarray:
    """Points where the branch wall meets the main wall (bisection along the branch wall)."""
    from wholearm_tools.geometry.base import perpendicular

    e1 = np.asarray(perpendicular(branch.axis))
    e2 = np.cross(branch.axis, e1)
    out = []
    for phi in np.linspace(0.0, 2 * np.pi, samples, endpoint=False):
        radial = branch.radius * (np.cos(phi) * e1 + np.sin(phi) * e2)
        lo, hi = 0.0, 2.0  # inside the main bore at 0, outside far along the branch
        for _ in range(50):
            mid = 0.5 * (lo + hi)
            v = branch.point + mid * branch.axis + radial - main.point
            rho = np.linalg.norm(v - (v @ main.axis) * main.axis)
            lo, hi = (mid, hi) if rho < main.radius else (lo, mid)
        out.append(branch.point + lo * branch.axis + radial)
    return np.array(out)


def test_a_tiled_junction_stays_within_its_deviation_of_the_ideal_bores() -> None:
    """Inside a junction of two bores the tiles never come closer than the ideal walls minus
    the measured deviation (which is within the requested one), and away from the lip, where
    the ideal clearance is exact, they are no farther either."""
    from wholearm_tools.geometry import Cylinder, CylinderJunction

    robot = RobotModel.from_spec({  # a short arm: only what it reaches is tiled
        "joints": [{"name": "yaw", "origin": [0, 0, 0.2], "radius": 0.03},
                   {"name": "pitch", "origin": [0, 0, 0.05], "axis": [0, 1, 0],
                    "radius": 0.02}],
        "tip": {"offset": [0.2, 0.0, 0.0], "radius": 0.02}}, name="short")
    main = Cylinder([0, 0, 0.3], [0, 0, 1], 0.14)
    branch = Cylinder([0, 0, 0.3], [0.7071, 0, 0.7071], 0.09)
    junction = CylinderJunction(main, branch, (-0.6, 0.6), (0.0, 0.6))
    scene = build_scene(robot, [junction], options(robot, max_deviation=1e-3))
    dev = max(scene.deviation.values())
    assert scene.tiles > 0
    assert set(scene.deviation) == {0, 1}
    assert dev <= 1e-3
    rng = np.random.default_rng(8)
    points = rng.uniform([-0.15, -0.15, 0.0], [0.45, 0.15, 0.6], size=(3000, 3))
    clearance = junction.clearance(points)
    near = (clearance > 0.003) & (clearance < 0.05)
    near &= np.linalg.norm(points - robot.base, axis=1) < robot.reach
    points, clearance = points[near][:120], clearance[near][:120]
    got = scene_distances(robot, [junction], points, farthest=0.06, scene=scene)
    assert np.all(got >= clearance - dev - 1e-6)  # no tile inside the ideal free space
    lip = lip_curve(main, branch)
    from_lip = np.min(np.linalg.norm(points[:, None] - lip[None], axis=2), axis=1)
    away = from_lip > clearance + 0.02
    assert away.sum() > 30
    np.testing.assert_allclose(got[away], clearance[away], atol=dev + 1e-6)


def test_the_drives_play_is_learned_from_the_wall_the_arm_pressed() -> None:
    """Pressed with the elbow bent either way, one wall is read at depths that differ by the
    play closed on opposite sides.  Learned from the map, the play comes within 0.3 mrad of
    the 2 mrad simulated and the wall comes back within 0.2 mm; told the play instead, the
    learning refuses to learn it again."""
    from wholearm_tools.calibration import estimate_drives
    from wholearm_tools.pipeline import reconstruct

    robot = two_link()
    on_wall = np.array([[0.55, -0.3], [0.55, 0.0], [0.55, 0.3]])
    res = run_scripted(robot, wall(0.55), pushes_across_a_wall(), home=(1.0, 0.0),
                       physics=Physics(joint_backlash=0.002), duration=40.0)
    read = reconstruct(res.run, B=0.02, workers=1)
    learned = estimate_drives(read, compliance=False, backlash=True)
    assert learned.learned == ("backlash",)
    assert learned.readings >= 6
    np.testing.assert_allclose(learned.backlash, 0.002, atol=3e-4)
    np.testing.assert_array_equal(learned.compliance, 0.0)     # not learned: the robot's
    rec = reconstruct(res.run, B=0.02, workers=1, learn_backlash=True)
    np.testing.assert_allclose(rec.surface_map.meta["joint_backlash"], 0.002, atol=3e-4)
    off = [np.abs(r.surface_map.primitives[0].primitive.signed_distance(on_wall)).max()
           for r in (read, rec)]
    assert off[0] > 5e-4     # read at the drives' angles
    assert off[1] < 2e-4     # at the links'
    assert "backlash learned from" in rec.messages[-1]
    told = dataclasses.replace(res.run, robot=dataclasses.replace(robot, joint_backlash=0.002))
    with pytest.raises(InputError, match="backlash is given"):
        reconstruct(told, B=0.02, workers=1, learn_backlash=True)
