"""Visualisation: trajectory and error plots, match drawings (matplotlib, Agg backend)."""
