"""Box obstacles placed and sized in the scene ("obstacles
(boxes placed and sized in the scene with viser's transform controls)").

The editor lives in the scene panel of a plan whose params take box
obstacles (``blast``'s ``obstacles``: a list of ``{lo_m, hi_m, name}``,
axis-aligned, world frame).  "Edit obstacles" turns the plan's boxes into
editable ones: each gets a translation gizmo (viser transform controls) and
can be selected, resized ("Size (m)") or removed; "Add box" puts a new one
at the plan's centre.  "Propose obstacles" proposes the plan again with the
boxes as they stand now — a proposal like any scene pick, which only an
operator's Accept turns into a plan (the params model checks the boxes then).
The box positions are read from the gizmos when proposing, so a drag in any
viewer counts.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from server.scene.context import DrawContext

#: Edge of a new box (m).
NEW_BOX_M = 0.2
#: Smallest edge a box may be given (m).
MIN_EDGE_M = 0.01
_EDIT_RGB = (240, 150, 40)
_SELECTED_RGB = (250, 210, 60)


@dataclass
class _Box:
    gizmo: Any  # viser TransformControlsHandle: its position is the box centre
    size: np.ndarray  # (3,) edge lengths, m
    name: str


class ObstacleEditor:
    """The scene controls that edit ``field`` (a list of boxes) of the plan
    drawn in ``ctx``; ``boxes`` are its current ones as (lo, hi, name),
    ``static`` the handles that draw them (hidden while editing), ``centre``
    where "Add box" puts a new one."""

    def __init__(
        self,
        ctx: DrawContext,
        boxes: list[tuple[np.ndarray, np.ndarray, str]],
        centre: np.ndarray,
        *,
        field: str = "obstacles",
        static: list[Any] | None = None,
    ) -> None:
        self.ctx = ctx
        self.field = field
        self.centre = np.asarray(centre, dtype=float)
        self._initial = [(np.asarray(lo, float), np.asarray(hi, float), n) for lo, hi, n in boxes]
        self._static = list(static or [])  # the plan's drawn boxes, hidden while editing
        self.boxes: list[_Box] = []
        self.selected: int | None = None
        self.editing = False
        self.last_proposal: str | None = None
        self._serial = 0
        gui = ctx.gui
        folder = gui.add_folder("Obstacles")
        ctx.gui_handles.append(folder)  # removing it removes its controls
        with folder:
            self.edit_box = gui.add_checkbox("Edit obstacles", initial_value=False)
            self.add_button = gui.add_button("Add box", disabled=True)
            self.size_input = gui.add_vector3(
                "Size (m)",
                initial_value=(NEW_BOX_M,) * 3,
                min=(MIN_EDGE_M,) * 3,
                step=0.01,
                disabled=True,
            )
            self.remove_button = gui.add_button("Remove selected", disabled=True)
            self.propose_button = gui.add_button("Propose obstacles", disabled=True)
        self.edit_box.on_update(lambda _: self.set_editing(bool(self.edit_box.value)))
        self.add_button.on_click(lambda _: self.add(self.centre, np.full(3, NEW_BOX_M)))
        self.size_input.on_update(lambda _: self.resize(np.asarray(self.size_input.value)))
        self.remove_button.on_click(lambda _: self.remove_selected())
        self.propose_button.on_click(lambda _: self.propose())

    # ------------------------------------------------------------ editing
    def set_editing(self, on: bool) -> None:
        with self.ctx.lock:
            if on == self.editing:
                return
            self.editing = on
            for h in (self.add_button, self.size_input, self.remove_button, self.propose_button):
                h.disabled = not on
            for h in self._static:
                h.visible = not on
            if on:
                for lo, hi, name in self._initial:
                    self.add((lo + hi) / 2.0, hi - lo, name)
            else:
                for b in self.boxes:
                    b.gizmo.remove()
                self.boxes, self.selected = [], None

    def add(self, centre: np.ndarray, size: np.ndarray, name: str = "") -> int:
        """A new editable box; it becomes the selected one."""
        with self.ctx.lock:
            self._serial += 1
            node = f"{self.ctx.root}/edit_obstacles/box{self._serial}"
            size = np.maximum(np.asarray(size, dtype=float), MIN_EDGE_M)
            gizmo = self.ctx.scene.add_transform_controls(
                node,
                scale=float(max(0.3, 1.5 * size.max())),
                disable_rotations=True,
                position=tuple(float(v) for v in centre),
            )
            self.boxes.append(_Box(gizmo, size, name or f"box {len(self.boxes) + 1}"))
            k = len(self.boxes) - 1
            self.select(k)
            return k

    def _draw(self, k: int) -> None:
        b = self.boxes[k]
        mesh = self.ctx.scene.add_box(
            f"{b.gizmo.name}/mesh",
            color=_SELECTED_RGB if k == self.selected else _EDIT_RGB,
            dimensions=tuple(float(v) for v in b.size),
            opacity=0.45,
        )
        mesh.on_click(lambda _, box=b: self.select(self.boxes.index(box)))

    def select(self, k: int) -> None:
        with self.ctx.lock:
            before, self.selected = self.selected, k
            for i in {k, before} - {None}:
                if i is not None and i < len(self.boxes):
                    self._draw(i)
            self.size_input.value = tuple(float(v) for v in self.boxes[k].size)

    def resize(self, size: np.ndarray) -> None:
        with self.ctx.lock:
            if self.selected is None or not np.all(np.isfinite(size)):
                return
            b = self.boxes[self.selected]
            new = np.maximum(size, MIN_EDGE_M)
            if np.array_equal(new, b.size):
                return
            b.size = new
            self._draw(self.selected)

    def remove_selected(self) -> None:
        with self.ctx.lock:
            if self.selected is None:
                return
            self.boxes.pop(self.selected).gizmo.remove()
            self.selected = None
            if self.boxes:
                self.select(len(self.boxes) - 1)

    # ----------------------------------------------------------- proposing
    def current(self) -> list[dict[str, Any]]:
        """The boxes as the params model takes them (corners rounded to 0.1 mm)."""
        out = []
        for b in self.boxes:
            c = np.asarray(b.gizmo.position, dtype=float)
            lo, hi = c - b.size / 2.0, c + b.size / 2.0
            out.append(
                {
                    "lo_m": [round(float(v), 4) for v in lo],
                    "hi_m": [round(float(v), 4) for v in hi],
                    "name": b.name,
                }
            )
        return out

    def propose(self) -> str | None:
        """Propose the plan with the boxes as they stand (no boxes: none)."""
        self.last_proposal = self.ctx.propose({self.field: self.current()})
        return self.last_proposal
