"""SpecGen core: spectral (see docs/dev/architecture.md)."""
