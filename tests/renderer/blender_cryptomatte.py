# Blender's Cryptomatte node (CompositorNodeCryptomatteV2) picking mattes out of a tessera EXR, as a compositor would:
#   blender -b --factory-startup --python blender_cryptomatte.py -- IN.exr TYPE NAMES OUT.exr WIDTH HEIGHT
# writes to OUT.exr the matte of NAMES (comma-separated object or material names) from the Cryptomatte layers of
# type TYPE (CryptoObject, CryptoMaterial) of IN.exr, found by the EXR's cryptomatte/<key>/ metadata.
import sys

import bpy

exr, layer, names, out, width, height = sys.argv[sys.argv.index("--") + 1:]
img = bpy.data.images.load(exr)
scene = bpy.context.scene
# The scene itself is not rendered into the output (the compositor's tree has no render layer); a cheap engine.
scene.render.engine = "CYCLES"
scene.cycles.samples = 1
# A multi-layer EXR's size is not known to bpy before it is composited: given.
scene.render.resolution_x, scene.render.resolution_y = int(width), int(height)
scene.render.resolution_percentage = 100
scene.use_nodes = True
tree = scene.node_tree
for n in list(tree.nodes):
    tree.nodes.remove(n)
crypto = tree.nodes.new("CompositorNodeCryptomatteV2")
crypto.source = "IMAGE"
crypto.image = img
crypto.layer_name = layer
crypto.matte_id = names
comp = tree.nodes.new("CompositorNodeComposite")
tree.links.new(crypto.outputs["Matte"], comp.inputs["Image"])
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
scene.render.filepath = out
bpy.ops.render.render(write_still=True)
