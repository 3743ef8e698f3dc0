"""Seal leak rate of two rough bodies in SI units, with a confidence interval (docs/seal.md)."""
