"""What a person reads from a study: its tables in display units, its figures and the report folder."""
