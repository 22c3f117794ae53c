"""Metrics beyond MMSeg's (issue 6): reconstruction quality."""
