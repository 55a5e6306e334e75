// PSNR (dB, 8-bit RGB) of two PNG images of the same size, whole image and foreground
// (pixels where either image is not black), decoded by headless Chromium's own canvas.
//
//   node psnr.mjs A.png B.png
import { chromium } from "playwright-core";
import { readFileSync } from "node:fs";

const [a, b] = process.argv.slice(2);
if (!a || !b) {
  console.error("usage: node psnr.mjs A.png B.png");
  process.exit(2);
}
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  args: ["--headless", "--no-sandbox", "--disable-background-networking", "--disable-component-update"],
});
try {
  const page = await browser.newPage();
  const urls = [a, b].map((p) => "data:image/png;base64," + readFileSync(p).toString("base64"));
  const result = await page.evaluate(async ([ua, ub]) => {
    const pixels = async (url) => {
      const image = new Image();
      image.src = url;
      await image.decode();
      const canvas = new OffscreenCanvas(image.width, image.height);
      const context = canvas.getContext("2d", { colorSpaceConversion: "none" });
      context.drawImage(image, 0, 0);
      return { w: image.width, h: image.height, data: context.getImageData(0, 0, image.width, image.height).data };
    };
    const [p, q] = [await pixels(ua), await pixels(ub)];
    if (p.w !== q.w || p.h !== q.h) return { error: `sizes differ: ${p.w}x${p.h} vs ${q.w}x${q.h}` };
    let [all, fg, nAll, nFg] = [0, 0, 0, 0];
    for (let i = 0; i < p.data.length; i += 4) {
      let d2 = 0;
      let lit = false;
      for (let c = 0; c < 3; c++) {
        const d = p.data[i + c] - q.data[i + c];
        d2 += d * d;
        lit ||= p.data[i + c] > 0 || q.data[i + c] > 0;
      }
      all += d2;
      nAll += 3;
      if (lit) { fg += d2; nFg += 3; }
    }
    const psnr = (sum, n) => 10 * Math.log10((255 * 255) / Math.max(sum / Math.max(n, 1), 1e-12));
    return { width: p.w, height: p.h, psnr_db: psnr(all, nAll), foreground_psnr_db: psnr(fg, nFg), foreground_pixels: nFg / 3 };
  }, urls);
  console.log(JSON.stringify(result));
} finally {
  await browser.close();
}
