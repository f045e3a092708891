"""Automatic labelling (paper Sec. 4.3, Figs. 4b–4f, 5, 6): surfaces, hand- and robot-level classes."""
