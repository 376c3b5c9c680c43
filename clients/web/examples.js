// Built-in example jobs. proto/examples/ is not embedded in the daemon, so the Cornell box is copied here
// (from proto/examples/cornell.json; tests/browser checks that the two stay equal).

export const CORNELL = {
  "kind": "scene",
  "scene": {
    "materials": {
      "white": {
        "type": "lambert",
        "albedo": [0.725, 0.71, 0.68]
      },
      "red": {
        "type": "lambert",
        "albedo": [0.63, 0.065, 0.05]
      },
      "green": {
        "type": "lambert",
        "albedo": [0.14, 0.45, 0.091]
      },
      "light": {
        "type": "emission",
        "radiance": [17.0, 12.0, 4.0],
        "one_sided": true
      }
    },
    "objects": [
      {
        "shape": "rectangle",
        "material": "white",
        "corner": [0, 0, 0],
        "edge1": [0, 0, 0.5592],
        "edge2": [0.556, 0, 0]
      },
      {
        "shape": "rectangle",
        "material": "white",
        "corner": [0, 0.5488, 0],
        "edge1": [0.556, 0, 0],
        "edge2": [0, 0, 0.5592]
      },
      {
        "shape": "rectangle",
        "material": "white",
        "corner": [0, 0, 0.5592],
        "edge1": [0, 0.5488, 0],
        "edge2": [0.556, 0, 0]
      },
      {
        "shape": "rectangle",
        "material": "red",
        "corner": [0.556, 0, 0],
        "edge1": [0, 0, 0.5592],
        "edge2": [0, 0.5488, 0]
      },
      {
        "shape": "rectangle",
        "material": "green",
        "corner": [0, 0, 0],
        "edge1": [0, 0.5488, 0],
        "edge2": [0, 0, 0.5592]
      },
      {
        "shape": "rectangle",
        "material": "light",
        "corner": [0.343, 0.5487, 0.227],
        "edge1": [0, 0, 0.105],
        "edge2": [-0.13, 0, 0]
      },
      {
        "shape": "mesh",
        "material": "white",
        "positions": [0.13, 0.165, 0.065, 0.082, 0.165, 0.225, 0.24, 0.165, 0.272, 0.29, 0.165, 0.114, 0.13, 0.0, 0.065, 0.082, 0.0, 0.225, 0.24, 0.0, 0.272, 0.29, 0.0, 0.114],
        "indices": [0, 1, 2, 0, 2, 3, 0, 4, 5, 0, 5, 1, 1, 5, 6, 1, 6, 2, 2, 6, 7, 2, 7, 3, 3, 7, 4, 3, 4, 0]
      },
      {
        "shape": "mesh",
        "material": "white",
        "positions": [0.423, 0.33, 0.247, 0.265, 0.33, 0.296, 0.314, 0.33, 0.456, 0.472, 0.33, 0.406, 0.423, 0.0, 0.247, 0.265, 0.0, 0.296, 0.314, 0.0, 0.456, 0.472, 0.0, 0.406],
        "indices": [0, 1, 2, 0, 2, 3, 0, 4, 5, 0, 5, 1, 1, 5, 6, 1, 6, 2, 2, 6, 7, 2, 7, 3, 3, 7, 4, 3, 4, 0]
      }
    ],
    "camera": {
      "from": [0.278, 0.273, -0.8],
      "to": [0.278, 0.273, 0],
      "up": [0, 1, 0],
      "fov_deg": 39.3077
    },
    "environment": {
      "color": [0, 0, 0]
    }
  },
  "render": {
    "width": 512,
    "height": 512,
    "spp": 256,
    "max_depth": 8,
    "estimator": "mis",
    "seed": 1
  },
  "outputs": ["png", "exr"]
};

// A material job: one material on the built-in preview stage.
export const MATERIAL_EXAMPLE = {
  kind: "material",
  material: { type: "lambert", albedo: [0.8, 0.3, 0.2] },
  render: { width: 256, height: 256, spp: 64, max_depth: 8, estimator: "mis", seed: 1 },
  outputs: ["png", "exr"],
};

export const EXAMPLES = [
  { id: "cornell", title: "Cornell box (scene)", name: "Cornell box", job: CORNELL },
  { id: "material", title: "Material preview: orange Lambert", name: "Orange Lambert", job: MATERIAL_EXAMPLE },
];
