"""Convective towers as cloud volumes (issue 17, docs/towers.md): Dobashi's cellular automaton
grown inside stacked ellipsoids, smoothed to a density. Pure: numpy and stdlib only."""
