"""Physical constants and conventions shared by the whole package.

Every other module takes these from here, so that a value is written once.
"""

__all__ = []

#: The spike camera's readout rate: one step every 25 us.
READOUT_HZ = 40_000.0

#: Spikes per readout step of a white pixel in the synthesized REDS spike
#: set, the intensity scale of the reconstruction literature
#: (``../shared/README.md``): "spike rate / 0.6 is the image", i.e. TFP's
#: gain is ``1 / REDS_WHITE_RATE``.
REDS_WHITE_RATE = 0.6

#: The firing threshold (in units of a white pixel's charge per step) that
#: gives the REDS scale in the simulator: white fires ``REDS_WHITE_RATE``
#: spikes per step.
REDS_THRESHOLD = 1 / REDS_WHITE_RATE

#: The image reconstructions by name (the tools' ``--method``): the trained
#: WGSE model, then the classical ones, each a function of
#: :mod:`.reconstruction_baselines` of that name (REDS scale);
#: ``wgse_mmseg.models.reconstruction.reconstruction_method`` makes each.
RECONSTRUCTION_METHODS = ('wgse', 'tfp', 'tfi', 'tfi_spatial_mean',
                          'tfi_temporal_mean')
