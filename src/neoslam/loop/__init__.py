"""Object keyframes and loop closure by graph matching (paper 3.2)."""
