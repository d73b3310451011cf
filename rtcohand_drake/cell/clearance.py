"""Clearance between the robot (arm, gripper, held part) and the cell (table, mold, glass).

`CellClearance` poses the cell's collision geometry at given joint angles (its
own MultibodyPlant and SceneGraph, the same models as the station) and answers
with SceneGraph's signed-distance queries: `min_distance(q)` is the closest any
robot geometry comes to the cell, and which pair that is (for scoring a run
log). The differential IK keeps its own clearance through Drake's collision
checker (`rtcohand_drake.systems.diff_ik`).
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import CollisionFilterDeclaration, Role
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.framework import DiagramBuilder

ROBOT = ("gen3", "gripper", "workpiece")
CELL = ("table", "mold", "safety_glass")


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

    def _pairs(self, q: np.ndarray, within_m: float):
        self.plant.SetPositions(self._plant_context, q)
        query = self.scene_graph.get_query_output_port().Eval(self._sg_context)
        for pair in query.ComputeSignedDistancePairwiseClosestPoints(within_m):
            a, b = pair.id_A, pair.id_B
            if a in self._robot_ids and b in self._cell_ids:
                yield pair, a, b
            elif b in self._robot_ids and a in self._cell_ids:
                yield pair, b, a

    def min_distance(self, q: np.ndarray, within_m: float = 0.1) -> tuple[float, str]:
        """The smallest robot-cell distance (m) and the pair ("robot geometry / cell geometry"); inf if none within."""
        best, which = float("inf"), ""
        for pair, robot_id, cell_id in self._pairs(q, within_m):
            if pair.distance < best:
                best = float(pair.distance)
                which = f"{self._inspector.GetName(robot_id)} / {self._inspector.GetName(cell_id)}"
        return best, which

