"""Model-based multi-object RGB-D pose tracking (paper, Section V-B), on the CPU."""
