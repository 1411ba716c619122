"""Loop closing: candidates by place recognition and geometric search on 2D
laser local maps (descriptor, local_maps, correlative, registration,
detector), loops listed by the recording (file_loops), the dead-reckoning
chain they are judged against (chain), and their factors (factors). The
checks of the loops (chain consistency, pairwise consistency, LOOP in the
diagnosis) are in validation.loops.

:func:`slam.loops.search.find_loops` is the entry point of the pipeline step.
"""
