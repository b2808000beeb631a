"""Protobuf schema of the AddBiomechanics binary subject format (.b3d), built at import.

The message classes are made from a descriptor assembled here in Python, so no ``protoc``
output is checked in and the only run-time dependency is the ``protobuf`` package
(any version with ``message_factory.GetMessageClass``: 4.22 and later; the project pins
>= 4.25). Nothing of nimblephysics is needed at run time.

Format reference (field numbers and types are interoperability facts taken from it):
keenon/nimblephysics ``dart/proto/SubjectOnDisk.proto`` (messages ``SubjectOnDiskHeader``,
``SubjectOnDiskTrialHeader``, ``SubjectOnDiskTrialProcessingPassHeader``,
``SubjectOnDiskPass``, ``SubjectOnDiskSensorFrame``, ``SubjectOnDiskProcessingPassFrame``).
The wire format does not depend on message or package names; ours live in the package
``addb.b3d`` in a private descriptor pool so they never clash with another copy of the
schema loaded in the same process.

Fields a newer writer adds that this schema does not know are kept by protobuf as unknown
fields and ignored.
"""

from __future__ import annotations

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

_F = descriptor_pb2.FieldDescriptorProto

# (name, number, type, repeated, enum or message type name)
_DOUBLE, _FLOAT, _INT32, _BOOL, _STRING = _F.TYPE_DOUBLE, _F.TYPE_FLOAT, _F.TYPE_INT32, _F.TYPE_BOOL, _F.TYPE_STRING
_ENUM, _MSG = _F.TYPE_ENUM, _F.TYPE_MESSAGE

#: Reasons a frame's ground reaction force is not trusted, by their number on disk.
MISSING_GRF_REASONS: tuple[str, ...] = (
    "notMissingGRF",
    "measuredGrfZeroWhenAccelerationNonZero",
    "unmeasuredExternalForceDetected",
    "torqueDiscrepancy",
    "forceDiscrepancy",
    "notOverForcePlate",
    "missingImpact",
    "missingBlip",
    "shiftGRF",
    "interpolatedClippedGRF",
    "manualReview",
)

#: Kinds of processing pass, by their number on disk.
PASS_TYPES: tuple[str, ...] = ("kinematics", "dynamics", "lowPassFilter")

_MESSAGES: dict[str, list[tuple[str, int, int, bool, str | None]]] = {
    # One processing pass of one trial: per-frame summaries stored in the header.
    "TrialPassHeader": [
        ("type", 1, _ENUM, False, "PassType"),
        ("dof_positions_observed", 2, _BOOL, True, None),
        ("dof_velocities_finite_differenced", 3, _BOOL, True, None),
        ("dof_acceleration_finite_differenced", 4, _BOOL, True, None),
        ("marker_rms", 5, _FLOAT, True, None),
        ("marker_max", 6, _FLOAT, True, None),
        ("linear_residual", 7, _FLOAT, True, None),
        ("angular_residual", 8, _FLOAT, True, None),
        ("joints_max_velocity", 9, _FLOAT, True, None),
        ("lowpass_cutoff_frequency", 10, _FLOAT, False, None),
        ("lowpass_filter_order", 11, _INT32, False, None),
        ("force_plate_cutoff", 12, _FLOAT, True, None),
    ],
    "TrialHeader": [
        ("name", 1, _STRING, False, None),
        ("missing_grf_reason", 2, _ENUM, True, "MissingGrfReason"),
        ("trial_length", 3, _INT32, False, None),
        ("trial_timestep", 4, _DOUBLE, False, None),
        ("processing_pass_header", 5, _MSG, True, "TrialPassHeader"),
        ("trial_tag", 6, _STRING, True, None),
        ("num_force_plates", 7, _INT32, False, None),
        ("force_plate_corners", 8, _DOUBLE, True, None),
        ("marker_names_guessed", 9, _BOOL, False, None),
        ("original_name", 10, _STRING, False, None),
        ("split_index", 11, _INT32, False, None),
    ],
    "Pass": [
        ("pass_type", 1, _ENUM, False, "PassType"),
        ("model_osim_text", 2, _STRING, False, None),
    ],
    "Header": [
        ("num_dofs", 1, _INT32, False, None),
        ("num_trials", 2, _INT32, False, None),
        ("raw_sensor_frame_size", 3, _INT32, False, None),
        ("processing_pass_frame_size", 4, _INT32, False, None),
        ("passes", 5, _MSG, True, "Pass"),
        ("ground_contact_body", 6, _STRING, True, None),
        ("custom_value_name", 7, _STRING, True, None),
        ("custom_value_length", 8, _INT32, True, None),
        ("trial_header", 9, _MSG, True, "TrialHeader"),
        ("version", 10, _INT32, False, None),
        ("href", 11, _STRING, False, None),
        ("notes", 12, _STRING, False, None),
        ("biological_sex", 13, _STRING, False, None),
        ("height_m", 14, _DOUBLE, False, None),
        ("mass_kg", 15, _DOUBLE, False, None),
        ("age_years", 16, _INT32, False, None),
        ("marker_name", 17, _STRING, True, None),
        ("acc_name", 18, _STRING, True, None),
        ("gyro_name", 19, _STRING, True, None),
        ("emg_name", 20, _STRING, True, None),
        ("emg_dim", 21, _INT32, False, None),
        ("exo_dof_index", 22, _INT32, True, None),
        ("subject_tag", 23, _STRING, True, None),
        ("num_joints", 24, _INT32, False, None),
    ],
    # One processing pass of one frame (fixed size on disk).
    "PassFrame": [
        ("pos", 1, _DOUBLE, True, None),
        ("vel", 2, _DOUBLE, True, None),
        ("acc", 3, _DOUBLE, True, None),
        ("tau", 4, _DOUBLE, True, None),
        ("ground_contact_wrench", 5, _DOUBLE, True, None),
        ("ground_contact_center_of_pressure", 6, _DOUBLE, True, None),
        ("ground_contact_torque", 7, _DOUBLE, True, None),
        ("ground_contact_force", 8, _DOUBLE, True, None),
        ("com_pos", 9, _DOUBLE, True, None),
        ("com_vel", 10, _DOUBLE, True, None),
        ("com_acc", 11, _DOUBLE, True, None),
        ("root_frame_residual", 12, _DOUBLE, True, None),
        ("root_frame_ground_contact_wrench", 14, _DOUBLE, True, None),
        ("root_frame_joint_centers", 15, _DOUBLE, True, None),
        ("world_frame_joint_centers", 16, _DOUBLE, True, None),
        ("root_frame_com_acc", 17, _DOUBLE, True, None),
        ("root_frame_ground_contact_center_of_pressure", 18, _DOUBLE, True, None),
        ("root_frame_ground_contact_torques", 19, _DOUBLE, True, None),
        ("root_frame_ground_contact_force", 20, _DOUBLE, True, None),
        ("root_frame_spatial_velocity", 21, _DOUBLE, True, None),
        ("root_frame_spatial_acceleration", 22, _DOUBLE, True, None),
        ("root_frame_root_pos_history", 23, _DOUBLE, True, None),
        ("root_frame_root_euler_history", 24, _DOUBLE, True, None),
    ],
    # The raw sensor readings of one frame (fixed size on disk).
    "SensorFrame": [
        ("custom_values", 1, _DOUBLE, True, None),
        ("marker_obs", 2, _DOUBLE, True, None),
        ("acc_obs", 3, _DOUBLE, True, None),
        ("gyro_obs", 4, _DOUBLE, True, None),
        ("emg_obs", 5, _DOUBLE, True, None),
        ("exo_obs", 6, _DOUBLE, True, None),
        ("raw_force_plate_cop", 7, _DOUBLE, True, None),
        ("raw_force_plate_torque", 8, _DOUBLE, True, None),
        ("raw_force_plate_force", 9, _DOUBLE, True, None),
    ],
}

#: Pass-frame fields whose length is not fixed by the header (kept as given, per frame).
PASS_EXTRA_FIELDS: tuple[str, ...] = tuple(
    name for name, number, *_ in _MESSAGES["PassFrame"] if number >= 12
)

_PACKAGE = "addb.b3d"


def _build() -> dict[str, type]:
    fdp = descriptor_pb2.FileDescriptorProto(name="addb_b3d_schema.proto", package=_PACKAGE, syntax="proto3")
    for enum_name, values in (("MissingGrfReason", MISSING_GRF_REASONS), ("PassType", PASS_TYPES)):
        enum = fdp.enum_type.add(name=enum_name)
        for number, value in enumerate(values):
            # enum value names are scoped to the package in protobuf: prefix them
            enum.value.add(name=f"{enum_name}_{value}", number=number)
    for msg_name, fields in _MESSAGES.items():
        msg = fdp.message_type.add(name=msg_name)
        for name, number, ftype, repeated, type_name in fields:
            f = msg.field.add(name=name, number=number, type=ftype)
            f.label = _F.LABEL_REPEATED if repeated else _F.LABEL_OPTIONAL
            if type_name is not None:
                f.type_name = f".{_PACKAGE}.{type_name}"
    pool = descriptor_pool.DescriptorPool()
    pool.Add(fdp)
    return {
        name: message_factory.GetMessageClass(pool.FindMessageTypeByName(f"{_PACKAGE}.{name}"))
        for name in _MESSAGES
    }


_CLASSES = _build()

Header = _CLASSES["Header"]
TrialHeader = _CLASSES["TrialHeader"]
TrialPassHeader = _CLASSES["TrialPassHeader"]
Pass = _CLASSES["Pass"]
SensorFrame = _CLASSES["SensorFrame"]
PassFrame = _CLASSES["PassFrame"]

__all__ = [
    "MISSING_GRF_REASONS",
    "PASS_EXTRA_FIELDS",
    "PASS_TYPES",
    "Header",
    "Pass",
    "PassFrame",
    "SensorFrame",
    "TrialHeader",
    "TrialPassHeader",
]
