"""SUMO as the world: the adapter (the only module that imports libsumo), the world, sensing,
planning, events, joins, traffic and the road set-up on a SUMO network (docs/architecture.md)."""
