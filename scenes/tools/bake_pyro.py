# Bakes a small Mantaflow fire with Blender, headless:
#   blender -b --factory-startup -P bake_pyro.py -- CACHE_DIR [RESOLUTION [FRAMES]]
# The cache (OpenVDB, one file per frame with every grid) lands in
# CACHE_DIR/data/. scenes/tools/bake_pyro.sh drives this, converts one frame
# to NanoVDB and renders it.
import sys
import bpy

argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
if not argv:
    sys.exit("usage: blender -b --factory-startup -P bake_pyro.py -- CACHE_DIR [RES [FRAMES]]")
cache_dir = argv[0]
resolution = int(argv[1]) if len(argv) > 1 else 40
frames = int(argv[2]) if len(argv) > 2 else 36

bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.frame_start = 1
scene.frame_end = frames

# The flow is built before the domain: Blender's fluid code crashes an
# operator that runs while a domain exists without any flow
# ('NoneType' object has no attribute 'getDataPointer').
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.18, location=(0.0, 0.0, 0.25))
flow = bpy.context.active_object
flow.name = "burner"
fm = flow.modifiers.new("Fluid", 'FLUID')
fm.fluid_type = 'FLOW'
fs = fm.flow_settings
fs.flow_type = 'BOTH'          # smoke and fire
fs.flow_behavior = 'INFLOW'
fs.flow_source = 'MESH'
fs.surface_distance = 1.0
fs.fuel_amount = 1.2
fs.density = 0.6
fs.temperature = 1.0

# Domain: 1 x 1 x 2 (Blender's z up), the burner near its floor.
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, 1.0))
domain = bpy.context.active_object
domain.name = "domain"
domain.scale = (1.0, 1.0, 2.0)
dm = domain.modifiers.new("Fluid", 'FLUID')
dm.fluid_type = 'DOMAIN'
ds = dm.domain_settings
ds.domain_type = 'GAS'
ds.resolution_max = resolution
ds.cache_type = 'ALL'
ds.cache_data_format = 'OPENVDB'
ds.openvdb_data_depth = '32'
ds.cache_directory = cache_dir
ds.cache_frame_start = 1
ds.cache_frame_end = frames
ds.use_adaptive_domain = False
ds.use_noise = False
ds.flame_vorticity = 0.6
ds.vorticity = 0.15
ds.burning_rate = 0.8
ds.flame_smoke = 0.6
ds.alpha = 1.0   # buoyancy of density
ds.beta = 1.5    # buoyancy of heat

bpy.context.view_layer.objects.active = domain
domain.select_set(True)
result = bpy.ops.fluid.bake_all()
print("bake_pyro: bake_all ->", result)
if 'FINISHED' not in result:
    sys.exit(1)
