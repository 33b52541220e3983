#!/usr/bin/env python3
"""Validates `material.usda` files written by `picker extract` with OpenUSD itself.

    pip install usd-core            # OpenUSD's Python bindings (PyPI wheel)
    python scripts/check-usd.py OUT/material.usda [OUT/material_1/material.usda ...]

For each file: opens the stage, runs every validator OpenUSD registers (UsdValidation:
stage metadata, shader property types against the Sdr definitions of UsdPreviewSurface,
UsdUVTexture and UsdPrimvarReader_float2, ...), checks that the default prim is a Material
whose surface output resolves to a UsdPreviewSurface, and that every shader input is one
its Sdr node declares, with the declared type. Prints one line per file; exits 1 on any
problem. Not part of CI (which needs only the Rust toolchain); `cargo test` checks the
file's structure without USD.
"""
import sys

from pxr import Sdr, Usd, UsdShade, UsdValidation


def check(path):
    problems = []
    stage = Usd.Stage.Open(path)
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    for e in context.Validate(stage):
        problems.append(f"{e.GetName()}: {e.GetMessage()}")
    prim = stage.GetDefaultPrim()
    if not prim or prim.GetTypeName() != "Material":
        return problems + ["the default prim is not a Material"]
    source = UsdShade.Material(prim).ComputeSurfaceSource()[0]
    if not source or source.GetIdAttr().Get() != "UsdPreviewSurface":
        problems.append("the surface output does not resolve to a UsdPreviewSurface")
    for child in prim.GetChildren():
        shader = UsdShade.Shader(child)
        node = Sdr.Registry().GetShaderNodeByIdentifier(shader.GetIdAttr().Get())
        if not node:
            problems.append(f"{child.GetPath()}: unknown shader id")
            continue
        for i in shader.GetInputs():
            declared = node.GetShaderInput(i.GetBaseName())
            if declared is None:
                problems.append(f"{child.GetPath()}: input {i.GetBaseName()} is not declared")
            elif declared.GetTypeAsSdfType().GetSdfType() != i.GetTypeName():
                problems.append(
                    f"{child.GetPath()}: input {i.GetBaseName()} is {i.GetTypeName()}, "
                    f"declared {declared.GetTypeAsSdfType().GetSdfType()}"
                )
    return problems


def main():
    bad = 0
    for path in sys.argv[1:]:
        problems = check(path)
        bad += bool(problems)
        print(f"{path}: " + ("ok" if not problems else "; ".join(problems)))
    sys.exit(1 if bad or len(sys.argv) < 2 else 0)


if __name__ == "__main__":
    main()
