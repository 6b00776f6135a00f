"""Small example procedures (the README shows table_spin)."""
