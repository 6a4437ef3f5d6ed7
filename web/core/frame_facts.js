// What a frame really is, from its header: the size of the ray grid the server rendered
// (the viewport × quality.image_scale, renderer/common/frame_renderer.cpp's raysForScale), the
// view it fills, and its level. The server sends a frame at its ray grid's size, with the
// view's size beside it (view_width, view_height), and the canvas scales it up; an older
// server sent every frame at the view's size, scaled up on the server.

// The server's raysForScale: max(1, lround(pixels · scale)).
export function raysForScale(pixels, scale) {
  return Math.max(1, Math.round(pixels * scale));
}

// {rendered: [w, h], sent: [w, h], view: [w, h], scale, level, final, codec, mip, step}
export function frameFacts(header) {
  const q = header.quality ?? {};
  const scale = Number.isFinite(q.image_scale) && q.image_scale > 0 ? q.image_scale : 1;
  const hasView = Number.isInteger(header.view_width) && Number.isInteger(header.view_height);
  const view = hasView ? [header.view_width, header.view_height] : [header.width, header.height];
  return {
    rendered: hasView ? [header.width, header.height] : [raysForScale(header.width, scale), raysForScale(header.height, scale)],
    sent: [header.width, header.height],
    view,
    scale,
    level: header.level,
    final: !!header.final,
    codec: header.codec,
    mip: Number.isInteger(q.mip_level) ? q.mip_level : null,
    step: Number.isFinite(q.step) ? q.step : null,
  };
}

const fmtScale = (s) => (s === 0.5 ? "½" : s === 0.25 ? "¼" : String(Number(s.toPrecision(3))));

// The overlay's two lines: the image as rendered (and the view it fills, or the size an older
// server sent it at, when that differs) and the level.
export function describeFrame(header) {
  const f = frameFacts(header);
  const [rw, rh] = f.rendered, [sw, sh] = f.sent, [vw, vh] = f.view;
  const image = rw === vw && rh === vh ? `${rw}×${rh}`
    : rw === sw && rh === sh ? `${rw}×${rh} (${fmtScale(f.scale)} scale of ${vw}×${vh})`
      : `${rw}×${rh} (${fmtScale(f.scale)} scale, sent as ${sw}×${sh})`;
  // A pass at rest comes after the final frame, toward the exact integral.
  const rest = Number.isInteger(header.rest_pass) && header.rest_pass > 0 ? ` · at rest, pass ${header.rest_pass}` : "";
  const parts = [`${f.level}${f.final ? " · final" : ""}${rest}`];
  if (f.mip !== null && f.mip > 0) parts.push(`mip ${f.mip}`);
  if (f.step !== null) parts.push(`step ${Number(f.step.toPrecision(3))}`);
  return { image, level: `${parts.join(" · ")} (${f.codec})` };
}
