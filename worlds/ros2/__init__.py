"""ROS 2 robots on the bus, as rmw_zenoh writes them, with no ROS install: wire names and tokens
(`names`), the sample attachment (`attachment`), CDR messages (`cdr`), a session that carries
attachments and tokens (`rosbus`), the robot file (`robot_file`), the world that serves a robot to
the agent (`world`), the agent's own ROS 2 entities (`presence`) and a stand-in arm (`standin`).

`rosbags` is imported only here (DESIGN.md, ROS 2 robots)."""
