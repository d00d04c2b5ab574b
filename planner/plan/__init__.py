"""Stage 1, make the plan: search the mission, choose and sharpen boundary pairs, dither them, export and report."""
