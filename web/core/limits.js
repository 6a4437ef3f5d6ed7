// The server's limits in the user's words. A `too_large` error names the server flag that
// set the limit (protocol/README.md, "Admission"), which a script wants and a user does not:
// the page says what was too large about the picture and what to do, and keeps the server's
// message for a tooltip. A frame the automatic policy lowered to fit the limits says what it
// lowered (frame header `limited`); the stats overlay shows that.

// {title, detail} for a `too_large` error `e` ({code, message, request_type}).
export function tooLargeWords(e) {
  const m = String(e?.message ?? "");
  if (/--max-samples-per-frame/.test(m))
    return {
      title: "This picture needs more rendering work than the server allows for one frame",
      detail: "Choose Automatic quality (it lowers the resolution to fit), a larger step, or a smaller window.",
    };
  if (/--max-request-mib/.test(m))
    return {
      title: "This picture needs more image memory than the server allows for one view",
      detail: "Choose Automatic quality (it lowers the resolution to fit), a lower image scale, or a smaller window.",
    };
  if (/--max-still-pixels/.test(m))
    return { title: "The saved picture would be larger than the server allows", detail: "Save a smaller picture." };
  if (/max_image_side|max_image_pixels/.test(m))
    return { title: "The window is larger than the server draws", detail: "Make the window or the picture smaller." };
  return { title: "The request was too large for the server", detail: "" };
}

// The overlay's line for a frame header: what was lowered and why, or "" when nothing was.
export function limitedLine(header) {
  const l = header?.limited;
  return typeof l === "string" && l ? l : "";
}
