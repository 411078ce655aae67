"""Every method hsp trains or evaluates, by name; imports nothing (``hsp report`` reads it)."""

HIERARCHY = ("proposed", "supervised")
"""π_h, π_m, π_l learnt from the pseudo-labels, and from the demonstrator's annotation (upper bound)."""
BASELINES = ("bc", "bc-rnn", "taco", "gail", "act", "diffusion")
"""The baselines of :mod:`hsp.baselines`."""
METHODS = ("oracle", *HIERARCHY, *BASELINES)
"""In the order the reports list them; ``oracle`` is the demonstrator's own plan."""
