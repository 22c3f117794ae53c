"""On-the-fly spike simulation as a data transform (issue 4): SimulateSpikes."""
