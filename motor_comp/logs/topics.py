"""Where a run's signals are in a bag: the topics and joint of DESIGN.md §6 "Runs from robots".

A recording of our own nodes has the §5 topics (``/axis/joint_states``,
``/axis/voltage``, ``/axis/reference``, one joint named ``axis``).  A robot's bag has
its own: one ``/joint_states`` with every joint, the drive input as the joints' effort,
a controller's state as the reference.  :class:`RunTopics` says which topic and joint
each signal of a :class:`~motor_comp.logs.run.Run` comes from; the readers
(:func:`~motor_comp.logs.mcap_io.read_run`, the streaming reader) take it.
"""
from __future__ import annotations

import dataclasses

from motor_comp.errors import ParameterError
from motor_comp.logs import schemas

#: ``--input effort``: the joint's own effort field is the drive input
EFFORT = 'effort'
#: default joint name of the §5 topics
AXIS_JOINT = 'axis'


@dataclasses.dataclass(frozen=True)
class RunTopics:
    """The topics and joints a run's signals are read from.

    Parameters
    ----------
    joint_states : tuple of str
        Candidate ``sensor_msgs/JointState`` topics of the measurement; the first one
        the bag has messages on is used.
    joint : str
        Joint to take from multi-joint messages (matched by name in every message:
        the order may change between messages).
    strict : bool
        The joint was named by the user: a message without it is an error, even a
        one-joint message.  Otherwise a one-joint message is taken whatever its name.
    input : str or None
        Topic of the drive input (``std_msgs/Float64``-like ``data``, or a JointState
        whose effort of ``input_joint`` is taken); None: the measured joint's effort.
    input_joint : str
        Joint of a JointState input topic.
    reference : str
        Topic of the reference: a JointState, or a ``control_msgs``
        ``JointTrajectoryControllerState`` (its ``reference``, or ``desired`` before
        Iron).
    reference_joint : str
        Joint of the reference.
    reference_given : bool
        The reference was named by the user: its absence is an error, not a warning.
    """

    joint_states: tuple[str, ...] = ('/axis/joint_states',)
    joint: str = AXIS_JOINT
    strict: bool = False
    input: str | None = '/axis/voltage'
    input_joint: str = AXIS_JOINT
    reference: str = '/axis/reference'
    reference_joint: str = AXIS_JOINT
    reference_given: bool = False

    @classmethod
    def of(cls, *, namespace: str = 'axis', topic: str | None = None,
           joint: str | None = None, input: str | None = None,
           reference: str | None = None) -> RunTopics:
        """Build the selection from the CLI's ``--topic --joint --input --reference``.

        Defaults (DESIGN.md §6): the joint states on ``/<namespace>/joint_states``, then
        ``/joint_states``; the input on ``/<namespace>/voltage``; the reference on
        ``/<namespace>/reference``; the joint ``axis`` (or the only one).
        """
        names = schemas.topics(namespace)
        if topic is not None:
            states: tuple[str, ...] = (_topic(topic, '--topic'),)
        else:
            states = tuple(dict.fromkeys((names['joint_states'], '/joint_states')))
        if joint is not None and (not joint or joint != joint.strip()):
            raise ParameterError(f'--joint: not a joint name: {joint!r}')
        the_joint = joint if joint is not None else AXIS_JOINT
        in_topic: str | None = names['voltage']
        in_joint = the_joint
        if input is not None:
            if input == EFFORT:
                in_topic = None
            else:
                in_topic, in_joint = _topic_joint(input, '--input', the_joint)
        ref, ref_joint = names['reference'], the_joint
        if reference is not None:
            ref, ref_joint = _topic_joint(reference, '--reference', the_joint)
        return cls(joint_states=states, joint=the_joint, strict=joint is not None,
                   input=in_topic, input_joint=in_joint, reference=ref,
                   reference_joint=ref_joint, reference_given=reference is not None)

    @property
    def effort_input(self) -> bool:
        """True when the drive input is the measured joint's effort."""
        return self.input is None

    def describe_input(self) -> str:
        """Say where the drive input comes from (for messages)."""
        if self.input is None:
            return f'the effort of joint {self.joint!r} (--input effort)'
        return self.input


def _topic(text: str, option: str) -> str:
    text = text.strip()
    if not text or any(c.isspace() for c in text):
        raise ParameterError(f'{option}: not a topic name: {text!r}')
    return text if text.startswith('/') else '/' + text


def _topic_joint(text: str, option: str, default_joint: str) -> tuple[str, str]:
    """Split ``TOPIC[:JOINT]`` (a topic name has no colon)."""
    topic, sep, joint = text.partition(':')
    if sep and not joint:
        raise ParameterError(f'{option}: no joint after the colon in {text!r}')
    return _topic(topic, option), (joint if sep else default_joint)
