"""modaluq: modal parameters with their uncertainty (placeholder during bootstrap)."""
