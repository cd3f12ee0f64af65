"""SpecGen core: common (see docs/dev/architecture.md)."""
