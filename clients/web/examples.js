// The Example tab's jobs: every job of proto/examples/, which the daemon serves as one object keyed by file name
// (examples.json, compiled in from that folder), and the client's own material preview. A file added to
// proto/examples appears here with no copy of it kept in the client.

// A material job: one material on the built-in preview stage.
export const MATERIAL_EXAMPLE = {
  kind: "material",
  material: { type: "lambert", albedo: [0.8, 0.3, 0.2] },
  render: { width: 256, height: 256, spp: 64, max_depth: 8, estimator: "mis", seed: 1 },
  outputs: ["png", "exr"],
};

// The client's own examples, listed after the daemon's.
export const CLIENT_EXAMPLES = [
  { id: "material", title: "Material preview: orange Lambert", name: "Orange Lambert", job: MATERIAL_EXAMPLE },
];

// examples.json's jobs as the Example tab lists them, in file name order: { id, title, name, job }. An example is
// called by its document's name, else by its file's ("room_gap.json": "Room gap").
export function examplesFrom(files) {
  return Object.entries(files || {})
    .filter(([file, job]) => /\.json$/.test(file) && job && typeof job === "object")
    .sort(([a], [b]) => (a < b ? -1 : a > b ? 1 : 0))
    .map(([file, job]) => {
      const id = file.replace(/\.json$/, "");
      const words = id.replaceAll("_", " ");
      const name = job.name || words[0].toUpperCase() + words.slice(1);
      return { id, title: `${name} (${job.kind || "job"})`, name, job };
    });
}
