"""SpecGen core: generate (see docs/dev/architecture.md)."""
