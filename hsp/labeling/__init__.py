"""Pseudo-labels (paper, Section IV-A/B, Algorithm 1): which object is the tool o+, which
is the target o*, and which future relative pose is the way-point w, in every frame."""
