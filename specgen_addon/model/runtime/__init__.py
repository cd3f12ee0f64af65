"""SpecGen core: model runtime (see docs/dev/architecture.md)."""
