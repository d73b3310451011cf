"""Measuring runs and policies: inspection scoring, the context-reading check, reference policies."""
