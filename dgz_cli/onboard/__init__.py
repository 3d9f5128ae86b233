"""URDF/xacro → HandSpec: parse, compile, partition, excite, derive features."""
