"""The MMSeg layer, set up by importing this module: what a config names.

A config can only import modules (``custom_imports``), so importing this
one is the config's explicit opt-in, and the only module of the package
whose import changes the process: it calls
:func:`wgse_mmseg.register_all_modules`, which applies the compatibility
patches (before MMSeg is imported) and registers the layer's datasets,
transforms, models, metrics and hooks. The shipped
dataset base configs name it::

    custom_imports = dict(imports=['wgse_mmseg.mmseg_layer'],
                          allow_failed_imports=False)

Python code calls :func:`wgse_mmseg.register_all_modules` instead.
"""
from . import register_all_modules

register_all_modules()
