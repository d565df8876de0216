"""Visualisation with matplotlib (Agg backend): match drawings (:mod:`.matches`) and
trajectory, error and training-curve plots (:mod:`.plots`). Imported only by the code that
draws, so nothing else pulls in matplotlib."""
