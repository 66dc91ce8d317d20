"""The chair against a world's walls: ``add_world`` puts a ``wcdrive.plant.world.World``
into the plant's pymunk space, with the chair's ``footprint`` as a box on the chassis,
and ``Contacts`` keeps the collisions pymunk's solver reports.

``add_world`` adds the world's segments (radius 0) and circles as static shapes and the
footprint (``ChairParams.length`` x ``width``, centred ``footprint_ahead_of_axle`` ahead
of the axle) as a box on the chassis, without mass of its own; a ValueError if the
footprint overlaps the world at the start. pymunk's solver keeps the two apart: an
inelastic contact (elasticity 0, friction ``WALL_FRICTION``) that lets the footprint
rest at most ``CONTACT_SLOP`` into a wall (more for a few milliseconds after an impact:
``CONTACT_BIAS``). A collision handler on the space reports every contact to
``Contacts``, from within each step, on the kernel's path as on the Python one: a
collision starts when the chair, touching nothing, touches the world, and lasts while
it touches anything.

A run may touch the world thousands of times (a chair pushing along a wall), so
``Contacts`` keeps the figures over the run and a bounded set of ``records``: the first
``KEEP_FIRST`` collisions, which say when and where it started, and the
``KEEP_LARGEST`` largest impacts among the rest, which say how hard it got.
"""

from __future__ import annotations

import dataclasses
import heapq
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import pymunk

from wcdrive.plant.params import ChairParams

if TYPE_CHECKING:
    from wcdrive.plant.world import World

#: m: how far the footprint may sink into a wall before the solver pushes it back out
#: (pymunk's ``collision_slop``; its default, 0.1, is meant for pixels).
CONTACT_SLOP = 5e-4
#: The share of the overlap beyond ``CONTACT_SLOP`` left after a second (pymunk's
#: ``collision_bias``): a tenth is taken back every millisecond. The step of an impact
#: may carry the footprint up to its speed times the step into a wall (2.3 mm at
#: 2.5 m/s in 1 ms steps) before the contact is found; 30 ms on it is within 0.2 mm
#: of the slop.
CONTACT_BIAS = 0.9**1000
#: Coulomb friction between the footprint and a wall (a bumper sliding along it; assumed).
WALL_FRICTION = 0.3
#: s: a collision's impact is the normal impulse the world gives over this long from its
#: first touch: the rigid inelastic impact and the spinning wheels' momentum coming
#: through the tyres (a few steps), and little of the push that may follow.
IMPACT_WINDOW = 0.02
#: The collisions ``Contacts.records`` keeps: the first ones, and the largest impacts.
KEEP_FIRST, KEEP_LARGEST = 50, 10


@dataclass
class Contact:
    """One collision (``Contacts``): ``time`` (s) the end of the step in which the chair
    first touched; ``x``, ``y`` (m, map frame) the mean of that step's contact points;
    ``impact`` (N s) the normal impulse over its first ``IMPACT_WINDOW``; ``impulse``
    (N s) the normal impulse over it all and ``duration`` (s) how long it touched, so
    far."""

    time: float
    x: float
    y: float
    impact: float = 0.0
    impulse: float = 0.0
    duration: float = 0.0


class Contacts:
    """The chair's collisions with the world, as pymunk's solver gave them (a collision
    handler on the plant's space, called from within each step on both paths): the
    figures over the run, and ``records`` (at most ``KEEP_FIRST + KEEP_LARGEST + 1``)."""

    def __init__(self) -> None:
        self.count = 0
        """Collisions so far."""
        self.first_time: float | None = None
        """s: the first one's ``time`` (None: none)."""
        self.max_impact = 0.0
        """N s: the largest ``impact``."""
        self.total_impulse = 0.0
        """N s: the world's normal impulse on the chair over the run."""
        self.contact_time = 0.0
        """s: the steps in which the chair touched the world."""
        self._first: list[Contact] = []
        self._largest: list[tuple[float, int, Contact]] = []      # a min-heap by impact
        self._current: Contact | None = None
        self._touching = 0                                          # shapes touched now
        self._step_end = math.nan                                   # of the last step seen

    @property
    def touching(self) -> bool:
        """Whether the chair touches the world after the last step."""
        return self._touching > 0

    def records(self) -> list[Contact]:
        """Copies of the first ``KEEP_FIRST`` collisions, the ``KEEP_LARGEST`` largest
        impacts among the others that have ended, and the one going on, by time."""
        kept = {id(c): c for c in self._first}
        kept.update((id(c), c) for _, _, c in self._largest)
        if self._current is not None:
            kept[id(self._current)] = self._current
        return sorted((dataclasses.replace(c) for c in kept.values()), key=lambda c: c.time)

    def begin(self, time: float, x: float, y: float) -> None:
        """The chair started touching a shape in the step that ends at ``time``, at
        (``x``, ``y``)."""
        self._touching += 1
        if self._touching > 1:
            return
        contact = Contact(time, x, y)
        self._current = contact
        self.count += 1
        if self.first_time is None:
            self.first_time = time
        if len(self._first) < KEEP_FIRST:
            self._first.append(contact)

    def solved(self, time: float, dt: float, impulse: float) -> None:
        """The solver gave one shape's contact ``impulse`` (N s, normal) in the step of
        ``dt`` that ends at ``time``."""
        contact = self._current
        if contact is None:
            return
        if time != self._step_end:
            self._step_end = time
            self.contact_time += dt
            contact.duration = time - contact.time + dt
        self.total_impulse += impulse
        contact.impulse += impulse
        if time - contact.time < IMPACT_WINDOW - 0.5 * dt:
            contact.impact += impulse
            self.max_impact = max(self.max_impact, contact.impact)

    def separate(self) -> None:
        """The chair stopped touching a shape."""
        self._touching -= 1
        contact = self._current
        if self._touching > 0 or contact is None:
            return
        self._current = None
        if self.count > KEEP_FIRST:                # not among the first, which stay
            entry = (contact.impact, self.count, contact)
            if len(self._largest) < KEEP_LARGEST:
                heapq.heappush(self._largest, entry)
            elif entry[0] > self._largest[0][0]:
                heapq.heapreplace(self._largest, entry)


def footprint(params: ChairParams) -> list[tuple[float, float]]:
    """The footprint's corners in the chassis frame (m; x forward from the axle
    midpoint, y to the left), counter-clockwise from the rear right."""
    front = params.footprint_ahead_of_axle + 0.5 * params.length
    rear = params.footprint_ahead_of_axle - 0.5 * params.length
    half = 0.5 * params.width
    return [(rear, -half), (front, -half), (front, half), (rear, half)]


def add_world(space: pymunk.Space, body: pymunk.Body, params: ChairParams, world: World,
              contacts: Contacts, step_start: Callable[[], float]) -> pymunk.Poly:
    """The world's static shapes and the chair's footprint on ``body`` into ``space``, and
    the collision handler that fills ``contacts`` (module docstring); ``step_start``
    gives the plant's time at the start of the step being solved. Returns the
    footprint; a ValueError if it overlaps the world."""
    space.collision_slop = CONTACT_SLOP
    space.collision_bias = CONTACT_BIAS
    static = space.static_body
    shapes: list[pymunk.Shape] = [pymunk.Segment(static, (x0, y0), (x1, y1), 0.0)
                                  for x0, y0, x1, y1 in world.segments.tolist()]
    shapes += [pymunk.Circle(static, r, (cx, cy)) for cx, cy, r in world.circles.tolist()]
    box = pymunk.Poly(body, footprint(params))
    for shape in (*shapes, box):
        shape.elasticity = 0.0
        shape.friction = WALL_FRICTION
    space.add(*shapes, box)
    hits = space.shape_query(box)
    if hits:
        x, y = body.position
        points = hits[0].contact_point_set.points
        at = points[0].point_b if points else (x, y)
        raise ValueError(f"the chair's footprint at ({x:g}, {y:g}, {math.degrees(body.angle):g} "
                         f"deg) overlaps the world near ({at[0]:.3f}, {at[1]:.3f})")

    def step_end() -> tuple[float, float]:
        dt = space.current_time_step
        return step_start() + dt, dt

    def begin(arbiter: pymunk.Arbiter, _space: pymunk.Space, _data: object) -> None:
        points = arbiter.contact_point_set.points
        n = 2 * len(points) or 1
        contacts.begin(step_end()[0], sum(c.point_a.x + c.point_b.x for c in points) / n,
                       sum(c.point_a.y + c.point_b.y for c in points) / n)

    def post_solve(arbiter: pymunk.Arbiter, _space: pymunk.Space, _data: object) -> None:
        j, n = arbiter.total_impulse, arbiter.normal
        contacts.solved(*step_end(), abs(j.x * n.x + j.y * n.y))

    def separate(_arbiter: pymunk.Arbiter, _space: pymunk.Space, _data: object) -> None:
        contacts.separate()

    space.on_collision(None, None, begin=begin, post_solve=post_solve, separate=separate)
    return box
