"""``identcheck skeleton``: a skeleton from a trial alone (issue #23).

The markers are grouped into rigid segments (:mod:`~identcheck.infer.grouping`), the segments joined by the
minimum spanning tree over pairwise joint-fit residuals, O'Brien et al. 2000, section 3.3
(:mod:`~identcheck.infer.tree`), each joint typed from its motion (:mod:`~identcheck.infer.joint_types`), and
the result written as a model file the other verbs read (:mod:`~identcheck.infer.model_writer`);
:mod:`~identcheck.infer.workflow` runs the steps and :mod:`~identcheck.infer.result` holds the answer.
"""
