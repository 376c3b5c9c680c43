# The render passes Blender's compositor finds in a tessera EXR: the outputs of an Image node given the file,
#   blender -b --factory-startup --python blender_passes.py -- IN.exr OUT.txt
# writes their names to OUT.txt, one a line.
import sys

import bpy

exr, out = sys.argv[sys.argv.index("--") + 1:]
scene = bpy.context.scene
scene.use_nodes = True
node = scene.node_tree.nodes.new("CompositorNodeImage")
node.image = bpy.data.images.load(exr)
with open(out, "w") as f:
    for o in node.outputs:
        if o.enabled:
            f.write(o.name + "\n")
