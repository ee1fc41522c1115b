"""Vehicle factories and their parameter files."""
