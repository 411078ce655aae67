"""Seeing what the pipeline did: tracking overlays, label timelines, Rerun recordings."""
