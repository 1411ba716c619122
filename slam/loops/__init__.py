"""Loop closing: loops found, listed by the recording, or recognised, before they are judged.

Candidates by place recognition and geometric search on 2D laser local
maps (detector, local_maps; the matching itself is :mod:`slam.matching`'s),
loops listed by the recording (file_loops), and the dead-reckoning chain
they are judged against (chain). Their factors are :mod:`slam.graph.loop_factors`;
the checks of the loops (chain consistency, pairwise consistency, LOOP in
the diagnosis) are in :mod:`validation.loops`.

:func:`slam.loops.search.find_loops` is the entry point of the pipeline step.
"""
