"""Reading recorded runs and writing results."""
