"""Blender background check of an artex .glb (tests/blender/blender_test.sh):

    blender -b --factory-startup --python-exit-code 1 --python tests/blender/check_glb.py -- \
        FILE.glb --joints 17 --frames 60 --fps 30 [--texture] [--render OUT.png]

Imports the file with Blender's glTF importer, applying the workaround for Debian 12's
Blender 3.4.1 (its importer calls numpy.bool, removed in numpy 1.24: glTF-Blender-IO #1844,
fixed in 3.5), then checks the armature's bones, the animation's frame range, the embedded
texture and the shape keys of exact exports, and renders one frame (Cycles, CPU)."""
import argparse
import sys
import warnings

import bpy
import numpy

# The workaround: restore the alias the 3.4 importer uses (harmless on newer versions).
with warnings.catch_warnings():
    warnings.simplefilter("ignore", FutureWarning)  # numpy 1.24 warns when probing the alias
    if not hasattr(numpy, "bool"):
        numpy.bool = bool

argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
parser = argparse.ArgumentParser()
parser.add_argument("glb")
parser.add_argument("--joints", type=int, required=True)
parser.add_argument("--frames", type=int, default=0)
parser.add_argument("--fps", type=float, default=30.0)
parser.add_argument("--texture", action="store_true")
parser.add_argument("--shape-keys", type=int, default=0)
parser.add_argument("--render", default="")
args = parser.parse_args(argv)


def fail(message):
    print("check_glb: FAILED: " + message)
    sys.exit(1)


bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.context.scene.render.fps = int(round(args.fps))
bpy.ops.import_scene.gltf(filepath=args.glb)

armatures = [o for o in bpy.context.scene.objects if o.type == "ARMATURE"]
meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
if len(armatures) != 1 or len(meshes) != 1:
    fail(f"expected one armature and one mesh, found {len(armatures)} and {len(meshes)}")
bones = armatures[0].data.bones
# The skin's joints: the global-similarity node plus one bone per artex joint.
if len(bones) != args.joints + 1:
    fail(f"expected {args.joints + 1} bones, found {len(bones)}: {[b.name for b in bones]}")
print(f"check_glb: {len(bones)} bones, {len(meshes[0].data.vertices)} vertices")

if args.frames > 0:
    actions = list(bpy.data.actions)
    if not actions:
        fail("no animation imported")
    start, end = min(a.frame_range[0] for a in actions), max(a.frame_range[1] for a in actions)
    # Blender keys glTF times t at frame t * fps (+1 when the importer shifts to frame 1).
    if round(end - start) != args.frames - 1:
        fail(f"expected a frame range of {args.frames} frames, found {start}..{end}")
    print(f"check_glb: animation frames {start:g}..{end:g} at {args.fps:g} fps")

if args.texture:
    images = [i for i in bpy.data.images if i.size[0] > 0]
    if not images:
        fail("no texture image imported")
    print(f"check_glb: texture {images[0].size[0]} x {images[0].size[1]}")

if args.shape_keys:
    keys = meshes[0].data.shape_keys
    count = len(keys.key_blocks) - 1 if keys else 0  # minus the basis
    if count != args.shape_keys:
        fail(f"expected {args.shape_keys} shape keys (exact correctives), found {count}")
    print(f"check_glb: {count} shape keys")

if args.render:
    scene = bpy.context.scene
    camera_data = bpy.data.cameras.new("check_camera")
    camera = bpy.data.objects.new("check_camera", camera_data)
    scene.collection.objects.link(camera)
    camera.location = (0.0, -4.0, 1.0)  # glTF Y-up imports Z-up in Blender
    camera.rotation_euler = (1.5708, 0.0, 0.0)
    scene.camera = camera
    light = bpy.data.objects.new("check_light", bpy.data.lights.new("check_light", "SUN"))
    scene.collection.objects.link(light)
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 4
    scene.cycles.use_denoising = False  # Debian's Blender is built without OpenImageDenoise
    scene.render.resolution_x, scene.render.resolution_y = 160, 120
    scene.frame_set(scene.frame_start + max(0, args.frames // 2))
    scene.render.filepath = args.render
    bpy.ops.render.render(write_still=True)
    print(f"check_glb: rendered {args.render}")
print("check_glb: OK")
