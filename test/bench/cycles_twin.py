"""scenes/plume.rrv rebuilt in Blender's Cycles, rendered to a linear float
EXR. It runs inside Blender (tested with Debian 12's Blender 3.4.1):

  blender -b --factory-startup -P test/bench/cycles_twin.py -- \
      --vdb plume.vdb --out plume.exr [--spp 16] [--seed 1] [--res 64]
      [--step-rate 1] [--threads 1]

--vdb is the plume's grid as scenes/tools/plume_vdb.py writes it (density
values on rrv's sample points under Cycles' cell-centred placement).
--step-rate multiplies Cycles' ray-marching step, one voxel (1/63 m) at 1,
Cycles' default. The last line printed is "cycles_twin cpu S", the CPU time
of the whole process (all threads) spent in the render call: scene sync,
sampling and writing; the driver (cycles_compare.py) takes the sync out.

What is matched, and how:
  - camera: rrv's eye, look and up; fov is rrv's vertical field of view,
    the image square, no depth of field.
  - sky: a constant world of colour (0.15, 0.18, 0.25), strength 1; Cycles'
    background colour times strength is the radiance rays escape into.
  - light: rrv's quad as a mesh quad wound so that its normal is u x v
    (down), with Emission strength 40 on that side only (Backfacing cuts the
    other). rrv's quad is also an opaque diffuse grey of albedo 0.5 (its
    `default` material), so the quad gets a Diffuse BSDF of 0.5 as well.
  - medium: sigma_s = 4.5 * 20 * density (Volume Scatter, white,
    anisotropy 0) plus sigma_a = 0.5 * 20 * density (Volume Absorption,
    black: Cycles absorbs (1 - colour) * density), linear interpolation,
    the grid read at full precision with no clipping of thin voxels.
  - paths: 64 bounces in all and 64 volume (and diffuse) bounces, like rrv's
    maxdepth 64; no clamping, no denoiser, no adaptive sampling.
  - pixels: a box filter one pixel wide, as rrv spreads each sample over its
    own pixel only; view transform Standard, look None, exposure 0, and an
    EXR holds scene-linear values anyway.
Everything else is Cycles' default, its sampler (progressive multi-jitter in
3.4) and its volume sampling (multiple importance) included."""
import argparse, math, sys, time

import bpy
from mathutils import Matrix, Vector

EYE, LOOK, UP, FOV = (0.5, -2.1, 0.55), (0.5, 0.5, 0.45), (0, 0, 1), 40.0
SKY = (0.15, 0.18, 0.25)
QUAD_ORIGIN, QUAD_U, QUAD_V, QUAD_L = (1.1, 0.25, 2.2), (0, 0.5, 0), (0.5, 0, 0), 40.0
SIGMA_A, SIGMA_S, SCALE = 0.5, 4.5, 20.0


def node_tree(owner):
    owner.use_nodes = True
    tree = owner.node_tree
    tree.nodes.clear()
    return tree.nodes, tree.links


def camera(scene, res):
    data = bpy.data.cameras.new("camera")
    data.sensor_fit = "VERTICAL"
    data.angle_y = math.radians(FOV)
    obj = bpy.data.objects.new("camera", data)
    eye, look, up = Vector(EYE), Vector(LOOK), Vector(UP)
    forward = (look - eye).normalized()
    right = forward.cross(up).normalized()
    true_up = right.cross(forward)
    # A Blender camera looks down its local -z with local +y up.
    rot = Matrix((right, true_up, -forward)).transposed()
    obj.matrix_world = Matrix.Translation(eye) @ rot.to_4x4()
    scene.collection.objects.link(obj)
    scene.camera = obj
    scene.render.resolution_x = scene.render.resolution_y = res
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = scene.render.pixel_aspect_y = 1


def world(scene):
    w = bpy.data.worlds.new("sky")
    nodes, links = node_tree(w)
    bg = nodes.new("ShaderNodeBackground")
    bg.inputs["Color"].default_value = SKY + (1.0,)
    bg.inputs["Strength"].default_value = 1.0
    out = nodes.new("ShaderNodeOutputWorld")
    links.new(bg.outputs["Background"], out.inputs["Surface"])
    scene.world = w


def quad_light(scene):
    o, u, v = Vector(QUAD_ORIGIN), Vector(QUAD_U), Vector(QUAD_V)
    mesh = bpy.data.meshes.new("light")
    # Corners in this order give the face the normal u x v, rrv's lit side.
    mesh.from_pydata([o, o + u, o + u + v, o + v], [], [(0, 1, 2, 3)])
    mat = bpy.data.materials.new("light")
    nodes, links = node_tree(mat)
    geo = nodes.new("ShaderNodeNewGeometry")
    front = nodes.new("ShaderNodeMath")
    front.operation = "SUBTRACT"
    front.inputs[0].default_value = 1.0
    links.new(geo.outputs["Backfacing"], front.inputs[1])
    strength = nodes.new("ShaderNodeMath")
    strength.operation = "MULTIPLY"
    strength.inputs[1].default_value = QUAD_L
    links.new(front.outputs["Value"], strength.inputs[0])
    emit = nodes.new("ShaderNodeEmission")
    emit.inputs["Color"].default_value = (1, 1, 1, 1)
    links.new(strength.outputs["Value"], emit.inputs["Strength"])
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (0.5, 0.5, 0.5, 1)
    diffuse.inputs["Roughness"].default_value = 0.0
    add = nodes.new("ShaderNodeAddShader")
    links.new(emit.outputs["Emission"], add.inputs[0])
    links.new(diffuse.outputs["BSDF"], add.inputs[1])
    out = nodes.new("ShaderNodeOutputMaterial")
    links.new(add.outputs["Shader"], out.inputs["Surface"])
    mesh.materials.append(mat)
    scene.collection.objects.link(bpy.data.objects.new("light", mesh))


def plume(scene, vdb):
    vol = bpy.data.volumes.new("plume")
    vol.filepath = vdb
    vol.render.precision = "FULL"
    vol.render.space = "OBJECT"
    vol.render.step_size = 0.0  # automatic: one voxel
    vol.render.clipping = 0.0
    mat = bpy.data.materials.new("plume")
    mat.cycles.volume_interpolation = "LINEAR"
    nodes, links = node_tree(mat)
    density = nodes.new("ShaderNodeAttribute")
    density.attribute_name = "density"
    shaders = []
    for kind, sigma, colour in (("ShaderNodeVolumeScatter", SIGMA_S, 1.0),
                                ("ShaderNodeVolumeAbsorption", SIGMA_A, 0.0)):
        mul = nodes.new("ShaderNodeMath")
        mul.operation = "MULTIPLY"
        mul.inputs[1].default_value = sigma * SCALE
        links.new(density.outputs["Fac"], mul.inputs[0])
        node = nodes.new(kind)
        node.inputs["Color"].default_value = (colour, colour, colour, 1)
        if "Anisotropy" in node.inputs:
            node.inputs["Anisotropy"].default_value = 0.0
        links.new(mul.outputs["Value"], node.inputs["Density"])
        shaders.append(node)
    add = nodes.new("ShaderNodeAddShader")
    links.new(shaders[0].outputs[0], add.inputs[0])
    links.new(shaders[1].outputs[0], add.inputs[1])
    out = nodes.new("ShaderNodeOutputMaterial")
    links.new(add.outputs["Shader"], out.inputs["Volume"])
    vol.materials.append(mat)
    scene.collection.objects.link(bpy.data.objects.new("plume", vol))


def settings(scene, a):
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device = "CPU"
    c.samples = a.spp
    c.seed = a.seed
    c.use_animated_seed = False
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.max_bounces = c.volume_bounces = c.diffuse_bounces = c.transparent_max_bounces = 64
    c.volume_step_rate = a.step_rate
    # The step count per ray must not cut the march short at small steps.
    c.volume_max_steps = max(1024, int(4096 / a.step_rate))
    c.pixel_filter_type = "BOX"
    scene.render.filter_size = 1.0
    scene.render.film_transparent = False
    scene.render.threads_mode = "FIXED"
    scene.render.threads = a.threads
    scene.render.use_compositing = scene.render.use_sequencer = False
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    img = scene.render.image_settings
    img.file_format = "OPEN_EXR"
    img.color_mode = "RGB"
    img.color_depth = "32"
    img.exr_codec = "ZIP"
    scene.render.filepath = a.out
    scene.render.use_file_extension = False


def main():
    ap = argparse.ArgumentParser(prog="cycles_twin.py")
    ap.add_argument("--vdb", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--step-rate", type=float, default=1.0)
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else [])
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    camera(scene, a.res)
    world(scene)
    quad_light(scene)
    plume(scene, bpy.path.abspath(a.vdb))
    settings(scene, a)
    t0 = time.process_time()
    bpy.ops.render.render(write_still=True)
    print("cycles_twin cpu %.6f" % (time.process_time() - t0), flush=True)


main()
