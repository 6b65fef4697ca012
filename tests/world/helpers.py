"""Driving a physics world through time in tests: states every 20 ms, as a recorder would sample them."""

from __future__ import annotations

from teleprev.world.world import PhysicsWorld, WorldState

SAMPLE_NS = 20_000_000


def run(world: PhysicsWorld, seconds: float) -> list[WorldState]:
    """Advance the world `seconds` on its clock and return its state every 20 ms."""
    states = []
    end = world.time_ns + int(seconds * 1e9)
    while world.time_ns < end:
        world.advance_to(world.time_ns + SAMPLE_NS)
        states.append(world.state())
    return states
