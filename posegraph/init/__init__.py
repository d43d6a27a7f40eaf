"""Initial values: composition along a spanning tree, chordal relaxation, and the choice."""
