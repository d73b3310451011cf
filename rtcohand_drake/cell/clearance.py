"""Clearance between the robot (arm, gripper, held part) and the cell (table, mold, glass).

`CellClearance` poses the cell's collision geometry at given joint angles (its
own MultibodyPlant and SceneGraph, the same models as the station) and answers
two questions with SceneGraph's signed-distance queries:

- `close_pairs(q, within_m)`: every robot-cell geometry pair closer than
  `within_m`, with its distance d and the gradient g = dd/dq (1/m per rad),
  so that d changes at g . v under joint velocities v. The differential IK
  uses it to keep the arm from driving into the cell.
- `min_distance(q)`: the closest any robot geometry comes to the cell (for
  scoring a run log).

Controllers build their own copy, never the station's plant, so this works
the same against the hardware station.
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np
from pydrake.geometry import CollisionFilterDeclaration, Role
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import DiagramBuilder

ROBOT = ("gen3", "gripper", "workpiece")
CELL = ("table", "mold", "safety_glass")


@dc.dataclass
class ClosePair:
    distance: float  # m, signed (negative: penetrating)
    gradient: np.ndarray  # (7,) dd/dq
    robot: str  # the robot geometry's name
    cell: str  # the cell geometry's name


class CellClearance:
    def __init__(self, layout, robot: tuple[str, ...] = ROBOT, cell: tuple[str, ...] = CELL,
                 ignore: tuple[tuple[str, str], ...] = ()):
        """`layout`: the scenario's `cell` (where the table, mold and glass stand).
        `ignore`: (robot model, cell model) pairs left out, e.g. ("workpiece", "mold")."""
        from rtcohand_drake.cell.plant import add_cell_models

        builder = DiagramBuilder()
        self.plant, self.scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
        instances = add_cell_models(self.plant, layout)
        self.plant.Finalize()
        self._diagram = builder.Build()
        self._context = self._diagram.CreateDefaultContext()
        self._plant_context = self.plant.GetMyContextFromRoot(self._context)
        self._sg_context = self.scene_graph.GetMyContextFromRoot(self._context)
        inspector = self.scene_graph.model_inspector()
        self._inspector = inspector

        def geometries(names):
            bodies = [self.plant.get_body(i) for n in names for i in self.plant.GetBodyIndices(instances[n])]
            return self.plant.CollectRegisteredGeometries(bodies)

        robot_set, cell_set = geometries(robot), geometries(cell)
        # Only robot-cell pairs: nothing within the robot, nothing within the cell, and
        # nothing else in the cell (the inspector has no collision geometry).
        manager = self.scene_graph.collision_filter_manager(self._sg_context)
        declaration = CollisionFilterDeclaration().ExcludeWithin(robot_set).ExcludeWithin(cell_set)
        for a, b in ignore:
            declaration.ExcludeBetween(geometries((a,)), geometries((b,)))
        manager.Apply(declaration)
        self._robot_ids = set(inspector.GetGeometryIds(robot_set, Role.kProximity))
        self._cell_ids = set(inspector.GetGeometryIds(cell_set, Role.kProximity))
        self._body_of = {}
        for g in self._robot_ids | self._cell_ids:
            body = self.plant.GetBodyFromFrameId(inspector.GetFrameId(g))
            self._body_of[g] = (body, inspector.GetPoseInFrame(g))

    def _pairs(self, q: np.ndarray, within_m: float):
        self.plant.SetPositions(self._plant_context, q)
        query = self.scene_graph.get_query_output_port().Eval(self._sg_context)
        for pair in query.ComputeSignedDistancePairwiseClosestPoints(within_m):
            a, b = pair.id_A, pair.id_B
            if a in self._robot_ids and b in self._cell_ids:
                yield pair, a, pair.p_ACa, b, pair.p_BCb, pair.nhat_BA_W
            elif b in self._robot_ids and a in self._cell_ids:
                yield pair, b, pair.p_BCb, a, pair.p_ACa, -pair.nhat_BA_W

    def close_pairs(self, q: np.ndarray, within_m: float) -> list[ClosePair]:
        """Robot-cell pairs closer than `within_m`, each with dd/dq (see module doc)."""
        out = []
        world = self.plant.world_frame()
        for pair, robot_id, p_RC, cell_id, p_CC, n_W in self._pairs(q, within_m):
            # n_W points from the cell's witness point toward the robot's: d grows as the
            # robot's point moves along n_W (the cell is welded to the world).
            body, X_BG = self._body_of[robot_id]
            J = self.plant.CalcJacobianTranslationalVelocity(
                self._plant_context, JacobianWrtVariable.kV, body.body_frame(), X_BG @ p_RC, world, world)
            out.append(ClosePair(float(pair.distance), np.asarray(n_W) @ J,
                                 self._inspector.GetName(robot_id), self._inspector.GetName(cell_id)))
        return out

    def min_distance(self, q: np.ndarray, within_m: float = 0.1) -> tuple[float, str]:
        """The smallest robot-cell distance (m) and the pair ("robot geometry / cell geometry"); inf if none within."""
        best, which = float("inf"), ""
        for pair, robot_id, _, cell_id, _, _ in self._pairs(q, within_m):
            if pair.distance < best:
                best = float(pair.distance)
                which = f"{self._inspector.GetName(robot_id)} / {self._inspector.GetName(cell_id)}"
        return best, which


def hold_clearance(v: np.ndarray, pairs: list[ClosePair], min_clearance_m: float, approach_time_s: float,
                   passes: int = 4) -> tuple[np.ndarray, bool]:
    """Joint velocities v with what drives the robot into the cell removed.

    Each close pair may shrink at most at (d - min_clearance_m) / approach_time_s
    (so the approach slows to nothing at the margin), and not at all once
    inside it; nothing is ever pushed away. v is projected onto those
    half-spaces g . v >= -max(d - margin, 0) / T in turn (a few passes).
    Returns (v, whether anything was removed).
    """
    v = np.array(v, float)
    acted = False
    for _ in range(passes):
        changed = False
        for p in pairs:
            g = p.gradient
            gg = float(g @ g)
            if gg < 1e-12:
                continue
            bound = -max(p.distance - min_clearance_m, 0.0) / approach_time_s
            rate = float(g @ v)
            if rate < bound - 1e-12:
                v += (bound - rate) / gg * g
                changed = acted = True
        if not changed:
            break
    return v, acted
