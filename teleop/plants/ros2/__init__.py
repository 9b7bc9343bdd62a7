"""A robot over ROS 2 without rclpy (docs/ros2.md): ROS 2's messages as Cyclone DDS types
(:mod:`.messages`, :mod:`.type_hashes`, :mod:`.node`), the loop's plant on a ros2_control or
CRTK robot (:mod:`.ros2_plant`) and a simulated robot served on ROS 2
(:mod:`.simulated_robot`). The DDS library (the ``ros2`` extra) is imported by those
modules only: :mod:`.settings` and :mod:`.names` need none."""
