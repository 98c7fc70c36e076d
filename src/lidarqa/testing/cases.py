"""Edge-case inputs (placeholder, filled below)."""
