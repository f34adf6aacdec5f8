"""ROS 2 nodes: thin rclpy adapters over the core's step functions (DESIGN.md §5).

=================  ===========================================  ======================
node               calls (the only implementation of the law)   topics
=================  ===========================================  ======================
trajectory_node    ``Trajectory.at`` → compiled ``traj_eval``   pub ``reference``
plant_node         ``Plant.step/measure`` → ``plant_advance``,  pub ``joint_states``,
                   ``plant_measure``                            ``/clock``; sub
                                                                ``voltage``
controller_node    ``Controller.step`` → ``controller_step``    sub ``reference``,
                                                                ``joint_states``; pub
                                                                ``voltage``
recorder_node      ``McapRecorder.write_cdr`` (raw CDR)         sub all of the above
                                                                and ``/diagnostics``
monitor_node       ``workbench.monitor.window_health``          sub ``joint_states``,
                                                                ``voltage``; pub
                                                                ``/diagnostics``
=================  ===========================================  ======================

Topics live in the namespace ``axis`` (``--ros-args -r __ns:=/other`` for another
axis); ``/clock`` is global.  ``reference`` carries the desired acceleration [m/s²] in
``effort`` (JointState has no acceleration field; the adaptive law needs it).

Lockstep protocol (deterministic, sim time on ``/clock``): the plant publishes
``joint_states``(t_k), and ``/clock`` t_k every ``clock_every`` (10) ticks; the
trajectory publishes the references ahead (on a tick k: up to r(t_{k+64}), never past
the run's ``duration``), taking the ticks in 2 ms batches, so it is off the critical
path and wakes ~100× less often (lockstep steps/s 0.58 → 0.9 of a bare rclpy round
trip on the 2-core machine, ``bench/ros_loop.py``); the controller answers each measurement with
exactly one command once the reference of the same stamp is there; the plant applies
it for one period and publishes step k+1.  Before step 0 the plant waits until its
peers have matched (controller and recorder subscribe ``joint_states`` only after their
other inputs matched), so nodes can start in any order.  A lockstep run reproduces
:func:`motor_comp.control.simulate` bit for bit.

Realtime: wall-clock timers at the control rate (plant, trajectory).  The plant stamps
its samples on the grid t0 + k·T, the trajectory publishes the reference of each grid
point one period ahead, and the controller answers the newest measurement with the
reference of the same stamp (extrapolated from the latest if it is missing), skipping
a backlog.  If the plant process is descheduled for whole periods, its sim time slips
(the world pauses with the simulator); a late controller is physical (the plant holds
the last command).  ``realtime_priority`` (``motor-comp run --mode realtime``: 40)
runs the loop processes under SCHED_FIFO; measured command delay at the plant p99
0.8 ms, max 1.1 ms, against p99 1.1 ms, max 7.9 ms with normal scheduling
(``bench/ros_loop.py``).

QoS: reliable, depth 1000; publishers transient-local, subscribers volatile (so any
ROS tool's publisher matches).  All nodes spin a :class:`~motor_comp.nodes.common.
LeanLoop` (wait set over the hot subscriptions/timers) next to the executor, which
serves parameter services and other timers.  SIGINT/SIGTERM stop every node cleanly;
the recorder drains what is still arriving and finalises its MCAP.

Run parameters in the MCAP: the recorder queries the other nodes' parameters through
their parameter services and writes a ``params:<node>`` metadata record per node as
soon as they answer; runtime changes (``/parameter_events``) go into a
``parameter_changes`` record at the end.
"""

#: environment variable: the pid of the process that started a node; when it is gone
#: (the node is re-parented), the node stops as on SIGINT.  Set by ``NodeGroup``
#: (``motor-comp run``, the demo, the node tests), so a test run or a CLI that is killed
#: leaves no loop running on: an orphaned lockstep loop of a killed stress run had kept
#: publishing for 90 min in a ROS domain id that later runs reused.
PARENT_ENV = 'MOTOR_COMP_EXIT_WITH_PARENT'
