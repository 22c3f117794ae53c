"""Helpers of the MMSeg layer: loading configs with the package's overrides
(:mod:`.config`)."""
