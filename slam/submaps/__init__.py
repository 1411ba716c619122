"""Scan-to-submap constraints for laser SLAM on sparse 2D scans.

After Cartographer's 2D design (Hess, Kohler, Rapp, Andor, "Real-Time Loop
Closure in 2D LIDAR SLAM", ICRA 2016), written here in numpy and GTSAM:

1. *Local SLAM* (:mod:`slam.submaps.local`): the keyframes' scans, in
   order, are each found in the submap being built (a few metres of scans)
   by a correlative branch-and-bound search (:mod:`slam.matching.search`
   over :mod:`slam.matching.grid`) around the dead-reckoning step, refined
   by point-to-line ICP (:mod:`slam.matching.icp`), and inserted.
2. *Global SLAM* (:mod:`slam.submaps.graph`): each scan is also searched
   for in the finished submaps near its current estimate; matches close
   along the path undo local drift, matches far along it close loops. A
   pose graph, optimised as the run is walked, keeps the estimate good
   enough for small search windows; matches the graph cannot agree with
   are dropped.

The result is a list of constraints between keyframes (a submap's anchor
and a scan) that the pipeline adds to its graph: the local and near ones
as scan matching, gated with it; the loops through the loop observer
(``loops.source: submaps``).
"""
