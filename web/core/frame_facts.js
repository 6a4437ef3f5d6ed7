// What a frame really is, from its header: the size of the ray grid the server rendered
// (the viewport × quality.image_scale, renderer/common/frame_renderer.cpp's raysForScale), the size
// it was sent at (the server scales a reduced grid up to the viewport), and its level.

// The server's raysForScale: max(1, lround(pixels · scale)).
export function raysForScale(pixels, scale) {
  return Math.max(1, Math.round(pixels * scale));
}

// {rendered: [w, h], sent: [w, h], scale, level, final, codec, mip, step}
export function frameFacts(header) {
  const q = header.quality ?? {};
  const scale = Number.isFinite(q.image_scale) && q.image_scale > 0 ? q.image_scale : 1;
  return {
    rendered: [raysForScale(header.width, scale), raysForScale(header.height, scale)],
    sent: [header.width, header.height],
    scale,
    level: header.level,
    final: !!header.final,
    codec: header.codec,
    mip: Number.isInteger(q.mip_level) ? q.mip_level : null,
    step: Number.isFinite(q.step) ? q.step : null,
  };
}

const fmtScale = (s) => (s === 0.5 ? "½" : s === 0.25 ? "¼" : String(Number(s.toPrecision(3))));

// The overlay's two lines: the image as rendered (and sent, when that differs) and the level.
export function describeFrame(header) {
  const f = frameFacts(header);
  const [rw, rh] = f.rendered, [sw, sh] = f.sent;
  const image = rw === sw && rh === sh ? `${rw}×${rh}` : `${rw}×${rh} (${fmtScale(f.scale)} scale, sent as ${sw}×${sh})`;
  const parts = [`${f.level}${f.final ? " · final" : ""}`];
  if (f.mip !== null && f.mip > 0) parts.push(`mip ${f.mip}`);
  if (f.step !== null) parts.push(`step ${Number(f.step.toPrecision(3))}`);
  return { image, level: `${parts.join(" · ")} (${f.codec})` };
}
