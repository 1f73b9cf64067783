"""The paper's evaluation and more, on the ROS-free closed loop: experiments
(the paper's section IV: :mod:`.section_iv`), acceptance checks (:mod:`.acceptance`), Poincaré stability
(:mod:`.poincare`, :mod:`.stability`), push recovery (:mod:`.push_recovery`), figures
and the report."""
