"""Image reconstruction from spikes (issue 6): WGSE + residual blocks."""
