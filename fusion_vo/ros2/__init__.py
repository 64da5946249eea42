"""fusion-vo inside a ROS 2 stack: the ``fusion_vo`` node (``fusion-vo ros2``) and a player (``fusion-vo ros2-play``).

The modules that talk to ROS (:mod:`.node`, :mod:`.run`, :mod:`.conversions`, :mod:`.diagnostics`,
:mod:`.play`) import ``rclpy`` and the message packages of the ``ros2`` extra
(``pip install "fusion-vo[ros2]"``); only the two commands import them, so ``import fusion_vo`` never
needs ROS. :mod:`.settings` (the node's parameters, validated with the run configuration's schema),
:mod:`.sensors` (the sensors' calibrations and the fusion they feed), :mod:`.intake` and :mod:`.camera`
(the threads feeding the fusion) do not import ROS. The parameters,
topics, QoS and diagnostics are documented in ``docs/ros2.md``.
"""
