"""SpecGen core: photo (see docs/dev/architecture.md)."""
