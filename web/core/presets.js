// The server's display presets for a volume (protocol/README.md, the volume object's
// `modality`): every preset of every modality, each naming its modality, the default first.
// Pure functions for the preset picker (app/preset_picker.js): which modalities to offer,
// which presets belong to one, and the line under the picker saying what is shown and why.

import { displayNumber } from "./window_level.js";

// The modalities to offer, the server's choice first: its `modalities`, else (an older
// server) those its presets name, else its choice alone.
export function modalitiesOf(info) {
  if (!info) return [];
  if (Array.isArray(info.modalities) && info.modalities.length) return [...info.modalities];
  const seen = [info.name];
  for (const p of info.presets ?? []) if (p.modality && !seen.includes(p.modality)) seen.push(p.modality);
  return seen;
}

// The presets of `modality`, in the server's order. An older server's presets name no
// modality: they are all its chosen modality's.
export function presetsOfModality(info, modality) {
  return (info?.presets ?? []).filter((p) => (p.modality || info.name) === modality);
}

// The line under the picker: the modality shown and why, then the preset shown (or that the
// curve is the user's own). `modality` is the one shown, `preset` the one whose points the
// view has (null: a curve of the user's).
export function presetNote(info, { modality, preset }) {
  if (!info) return "";
  const source = info.source === "file" ? "from the file" : "inferred";
  const why = modality === info.name
    ? `${info.name} (${source}): ${info.reason}`
    : `${modality}, chosen by you (the server chose ${info.name}, ${source}: ${info.reason})`;
  if (!preset) return `${why} → your own curve`;
  const hu = info.hounsfield === true && (preset.modality || info.name) === "CT";
  const w = displayNumber(preset.window, { hounsfield: hu }), l = displayNumber(preset.level, { hounsfield: hu });
  return `${why} → ${preset.label}, W ${w} / L ${l}${hu ? " HU" : ""}${preset.shading ? ", shaded" : ""}`;
}
