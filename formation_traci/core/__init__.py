"""What every part of formation_traci builds on: the compiled kernels and their cache,
the leader state, the recorded versions, the interruption of a run by a signal."""
