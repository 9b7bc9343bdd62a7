"""The operator's input sources (docs/design.md section 19): the interface
(:mod:`.source`), the network master's protocol (:mod:`.protocol`), receiver (:mod:`.udp`)
and client (:mod:`.client`), the SpaceMouse (:mod:`.spacemouse`), the view mapping
(:mod:`.mapping`), the feedback wrench (:mod:`.feedback`)."""

from .client import MasterClient
from .feedback import FeedbackGains, feedback_wrench
from .mapping import DEFAULT_VIEW, device_pose, followed_pose, integrated_twist, view_rotation
from .protocol import (CLUTCH, MODE, Command, Feedback, FeedbackState, PacketError, as_key,
                       decode_command, decode_feedback, encode_command, encode_feedback,
                       new_key, read_key_file)
from .source import DROP_REASONS, InputSample, InputSource
from .udp import UdpMaster

__all__ = ["CLUTCH", "DEFAULT_VIEW", "Command", "DROP_REASONS", "Feedback", "FeedbackGains",
           "FeedbackState", "InputSample", "InputSource", "MODE", "MasterClient",
           "PacketError", "UdpMaster", "as_key", "decode_command", "decode_feedback",
           "device_pose", "encode_command", "encode_feedback", "feedback_wrench", "followed_pose",
           "integrated_twist", "new_key", "read_key_file", "view_rotation"]
