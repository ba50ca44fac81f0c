"""MuJoCo models generated from characters (``mujoco.MjSpec``) and MuJoCo replay."""

from mjcf.builder import build_spec, compile_model, to_xml

__all__ = ["build_spec", "compile_model", "to_xml"]
