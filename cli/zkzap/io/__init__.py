"""Output by format (writers), and the terminal helpers that decide colour and tables."""
