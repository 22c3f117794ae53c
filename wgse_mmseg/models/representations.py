"""Classical spike representations as enhancers (issue 5): TFP, TFI, mean filters."""
