# MMSeg's runtime, logging by epoch to match the epoch-based schedule.
_base_ = ['mmseg::_base_/default_runtime.py']
log_processor = dict(by_epoch=True)
