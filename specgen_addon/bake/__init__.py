"""SpecGen core: bake (see docs/dev/architecture.md)."""
