// Opens a page of the web viewer in headless Chromium, waits for its first frames (or an
// error) and writes what it saw: `<out>/report.json` (the page's data-nelf-* report, the
// backend, timings) and `<out>/view.png` (a screenshot of the 3D view's rectangle).
//
//   node shoot.mjs URL OUT_DIR webgpu|webgl2 [--fps SECONDS] [--drop FILE [--expect-error]] [--touch]
//
// webgpu: Chromium's WebGPU on SwiftShader (Vulkan); webgl2: WebGPU off, so the page
// gets WebGL2 only. --fps: after the screenshot, count frames for SECONDS of real time
// (the URL should say continuous=1). --drop: after the first frames, drop FILE on the
// canvas as a person would (a DragEvent carrying the file) and wait for the page to show
// an error or draw three more frames; the report is written after that. With
// --expect-error it waits for the error alone: a continuous page draws three frames
// sooner than a damaged file's error may show, so "three frames" would race it. --touch: after the
// first frames, three gestures on the 3D view by touch (Chromium's touch events, as a
// phone sends them): a finger held still for a second, then dragged to the right; a
// two-finger pinch apart; a two-finger drag down. The report's `touch` lists the page's
// camera before and after each.
import { chromium } from "playwright-core";
import { mkdirSync, readFileSync, writeFileSync } from "node:fs";
import { basename, join } from "node:path";

const [url, outDir, backend, ...rest] = process.argv.slice(2);
if (!url || !outDir || !["webgpu", "webgl2"].includes(backend)) {
  console.error("usage: node shoot.mjs URL OUT_DIR webgpu|webgl2 [--fps SECONDS]");
  process.exit(2);
}
const option = (name) => { const i = rest.indexOf(name); return i >= 0 ? rest[i + 1] : undefined; };
const fpsSeconds = Number(option("--fps") || 0);
const dropFile = option("--drop");
const expectError = rest.includes("--expect-error");
const touch = rest.includes("--touch");
const base = [
  "--headless", "--no-sandbox", "--disable-quic", "--no-first-run",
  "--disable-background-networking", "--disable-component-update", "--disable-sync",
  "--window-size=1024,768",
];
const gpu = backend === "webgpu"
  ? ["--enable-unsafe-webgpu", "--enable-features=Vulkan", "--use-vulkan=swiftshader", "--use-angle=swiftshader"]
  : ["--disable-features=WebGPU", "--use-angle=swiftshader"];
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  args: [...base, ...gpu],
});
const report = { url, backend };
try {
  const page = await browser.newPage({ viewport: { width: 1024, height: 768 }, deviceScaleFactor: 1, hasTouch: touch });
  const console_lines = [];
  page.on("console", (m) => console_lines.push(`${m.type()}: ${m.text()}`));
  page.on("pageerror", (e) => console_lines.push(`pageerror: ${e.message}`));
  const t0 = Date.now();
  await page.goto(url);
  // Three frames with the asset shown, or an error on the page.
  await page.waitForFunction(
    () => Number(document.body.dataset.nelfFrames || 0) >= 3 || (document.body.dataset.nelfError || "") !== "",
    null,
    { timeout: 240000, polling: 100 },
  );
  report.wait_ms = Date.now() - t0;
  if (dropFile && !(await page.evaluate(() => document.body.dataset.nelfError))) {
    const bytes = [...readFileSync(dropFile)];
    const name = basename(dropFile);
    const frames = await page.evaluate(([data, fileName]) => {
      const transfer = new DataTransfer();
      transfer.items.add(new File([new Uint8Array(data)], fileName));
      const canvas = document.getElementById("nelf_canvas");
      for (const type of ["dragenter", "dragover", "drop"]) {
        canvas.dispatchEvent(new DragEvent(type, { dataTransfer: transfer, bubbles: true, cancelable: true }));
      }
      return Number(document.body.dataset.nelfFrames || 0);
    }, [bytes, name]);
    await page.waitForFunction(
      ([before, errorOnly]) =>
        (document.body.dataset.nelfError || "") !== "" ||
        (!errorOnly && Number(document.body.dataset.nelfFrames || 0) >= before + 3),
      [frames, expectError],
      { timeout: 120000, polling: 100 },
    );
    report.dropped = name;
  }
  if (touch && !(await page.evaluate(() => document.body.dataset.nelfError))) {
    const cdp = await page.context().newCDPSession(page);
    const [x, y, width, height] = (await page.evaluate(() => document.body.dataset.nelfRect)).split(",").map(Number);
    const [cx, cy] = [x + width / 2, y + height / 2];
    const camera = () => page.evaluate(() => document.body.dataset.nelfCamera);
    const frames = () => page.evaluate(() => Number(document.body.dataset.nelfFrames || 0));
    // One touch event, then a frame drawn after it was sent (the page draws only on input,
    // and may already have drawn by the time CDP returns: count from before), so that a
    // slow frame on a loaded machine does not fold a whole gesture into one update.
    const send = async (type, points) => {
      const before = await frames();
      await cdp.send("Input.dispatchTouchEvent", {
        type,
        touchPoints: points.map(([px, py], id) => ({ x: px, y: py, id })),
      });
      await page.waitForFunction((n) => Number(document.body.dataset.nelfFrames || 0) > n, before, { timeout: 60000 });
    };
    // Fingers at `start`, held still for `holdMs`, moved by `step` per event, ten times,
    // then lifted; then the page is left to draw.
    const gesture = async (start, step, holdMs = 0) => {
      await send("touchStart", start);
      await page.waitForTimeout(holdMs);
      for (let i = 1; i <= 10; i++) {
        await send("touchMove", start.map(([px, py], f) => [px + i * step[f][0], py + i * step[f][1]]));
      }
      await send("touchEnd", []);
      await page.waitForTimeout(500);
    };
    report.touch = [await camera()];
    // The finger rests a second before it moves, longer than egui's press-and-hold (0.8 s,
    // a context-menu click on a view that senses clicks) and than a slow frame.
    await gesture([[cx, cy]], [[10, 0]], 1000);
    report.touch.push(await camera());
    await gesture([[cx - 40, cy], [cx + 40, cy]], [[-8, 0], [8, 0]]);
    report.touch.push(await camera());
    await gesture([[cx - 40, cy], [cx + 40, cy]], [[0, 8], [0, 8]]);
    report.touch.push(await camera());
  }
  report.data = await page.evaluate(() => ({ ...document.body.dataset }));
  report.message = await page.evaluate(() => document.getElementById("nelf_message")?.textContent || "");
  if (report.data.nelfRect && !report.data.nelfError) {
    const [x, y, width, height] = report.data.nelfRect.split(",").map(Number);
    await page.screenshot({ path: join(outDir, "view.png"), clip: { x, y, width, height } });
    if (fpsSeconds > 0) {
      const before = Number(await page.evaluate(() => document.body.dataset.nelfFrames));
      const start = Date.now();
      await page.waitForTimeout(fpsSeconds * 1000);
      const after = Number(await page.evaluate(() => document.body.dataset.nelfFrames));
      report.fps = (after - before) / ((Date.now() - start) / 1000);
      report.frame_ms = await page.evaluate(() => document.body.dataset.nelfFrameMs);
    }
  }
  report.console = console_lines;
} finally {
  await browser.close();
}
mkdirSync(outDir, { recursive: true });
writeFileSync(join(outDir, "report.json"), JSON.stringify(report, null, 2));
console.log(JSON.stringify(report.data || {}));
