// Drives the rbfsurf viewer like a person: drop a point file on the page, press Reconstruct,
// wait for "loaded N triangles", screenshot the canvas and check that it shows a mesh. The served
// GLB must be the compact one (KHR_mesh_quantization + EXT_meshopt_compression, decoded in the page
// by the vendored meshoptimizer decoder) and N its triangle count.
// Usage: node viewer.mjs BASE_URL POINT_FILE SCREENSHOT.png
import { chromium } from "playwright-core";
import { readFileSync, writeFileSync } from "node:fs";
import { inflateSync } from "node:zlib";
import { basename } from "node:path";

const [base, file, shot] = process.argv.slice(2);
const executablePath = process.env.CHROMIUM || "/usr/bin/chromium";
const flags = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
  "--disable-component-update", "--disable-sync", "--no-first-run",
  "--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"];

function fail(msg) { console.error("browser test FAILED: " + msg); process.exit(1); }

// Minimal PNG reader (8-bit RGB/RGBA, non-interlaced) → {width, height, channels, data}.
function decodePng(buf) {
  let off = 8, width = 0, height = 0, type = 0, idat = [];
  while (off < buf.length) {
    const len = buf.readUInt32BE(off), name = buf.toString("ascii", off + 4, off + 8);
    const body = buf.subarray(off + 8, off + 8 + len);
    if (name === "IHDR") {
      width = body.readUInt32BE(0); height = body.readUInt32BE(4);
      if (body[8] !== 8 || body[12] !== 0) throw new Error("unsupported PNG depth/interlace");
      type = body[9];
    } else if (name === "IDAT") idat.push(body);
    off += 12 + len;
  }
  const ch = type === 6 ? 4 : type === 2 ? 3 : 0;
  if (!ch) throw new Error("unsupported PNG colour type " + type);
  const raw = inflateSync(Buffer.concat(idat)), stride = width * ch;
  const out = Buffer.alloc(height * stride);
  for (let y = 0; y < height; y++) {
    const f = raw[y * (stride + 1)], src = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    for (let x = 0; x < stride; x++) {
      const a = x >= ch ? out[y * stride + x - ch] : 0, b = y ? out[(y - 1) * stride + x] : 0;
      const c = x >= ch && y ? out[(y - 1) * stride + x - ch] : 0;
      let p = a + b - c, pa = Math.abs(p - a), pb = Math.abs(p - b), pc = Math.abs(p - c);
      const pred = [0, a, b, (a + b) >> 1, pa <= pb && pa <= pc ? a : pb <= pc ? b : c][f];
      out[y * stride + x] = (src[x] + pred) & 255;
    }
  }
  return { width, height, channels: ch, data: out };
}

const browser = await chromium.launch({ executablePath, args: flags, headless: true });
try {
  const page = await browser.newPage({ viewport: { width: 1100, height: 700 } });
  const logs = [];
  page.on("console", (m) => logs.push(`[console.${m.type()}] ${m.text()}`));
  page.on("pageerror", (e) => logs.push(`[pageerror] ${e.message}`));
  page.on("request", (r) => { if (!r.url().startsWith(base)) logs.push(`[external request] ${r.url()}`); });
  await page.goto(base + "/", { waitUntil: "load" });
  // A real drop event carrying the file, as when a user drags it from the desktop.
  const bytes = [...readFileSync(file)];
  await page.evaluate(({ bytes, name }) => {
    const dt = new DataTransfer();
    dt.items.add(new File([new Uint8Array(bytes)], name));
    const drop = document.getElementById("drop");
    drop.dispatchEvent(new DragEvent("dragover", { dataTransfer: dt, bubbles: true, cancelable: true }));
    drop.dispatchEvent(new DragEvent("drop", { dataTransfer: dt, bubbles: true, cancelable: true }));
  }, { bytes, name: basename(file) });
  // Two levels of detail: the page shows them coarse to fine before the full mesh.
  await page.fill("#lods", "2");
  await page.click("#go");
  const status = page.locator("#status");
  try {
    await page.waitForFunction(() => /loaded \d+ triangles|failed|Cannot|error/i.test(document.getElementById("status").textContent),
      null, { timeout: 180000 });
  } catch (e) { fail("no result within 180 s; status: " + (await status.textContent()) + "\n" + logs.join("\n")); }
  const text = await status.textContent();
  const m = text.match(/loaded (\d+) triangles/);
  if (!m) fail(`page says "${text}"\n${logs.join("\n")}`);
  const shown = Number(m[1]);
  const stats = await page.locator("#stats").textContent();
  // The report counts the reconstructed mesh; the compact GLB merges vertices that share a 16-bit
  // grid point and drops the slivers between them (measured: 0.08 % of the kitten's triangles).
  const reported = Number((stats.match(/triangles(\d+)/) || [])[1]);
  if (!(reported >= shown && reported - shown <= 0.005 * reported))
    fail(`stats table lists ${reported} triangles, the page shows ${shown}: ${stats}`);
  // The file the page decoded: compact, and holding exactly the triangles the page reports.
  const id = (await page.evaluate(() => location.hash)).replace("#job=", "");
  const glb = Buffer.from(await (await fetch(`${base}/v1/reconstructions/${id}/mesh.glb`)).arrayBuffer());
  const doc = JSON.parse(glb.toString("utf8", 20, 20 + glb.readUInt32LE(12)));
  const required = doc.extensionsRequired || [];
  if (!required.includes("EXT_meshopt_compression") || !required.includes("KHR_mesh_quantization"))
    fail(`the served GLB is not compact: extensionsRequired ${JSON.stringify(required)}`);
  const inFile = doc.accessors[doc.meshes[0].primitives[0].indices].count / 3;
  if (inFile !== shown) fail(`the page shows ${shown} triangles, the GLB holds ${inFile}`);
  const streamed = logs.filter((l) => l.includes("level of detail"));
  if (streamed.length !== 2 || !streamed[0].includes("level of detail 2") || !streamed[1].includes("level of detail 1"))
    fail(`expected levels of detail 2 then 1 before the full mesh, saw ${JSON.stringify(streamed)}`);
  console.log(streamed.join("; "));
  console.log(`served GLB: ${glb.length} bytes, ${(glb.length / shown).toFixed(2)} bytes per triangle, ${required.join(" + ")}`);
  if (!(await page.locator("#links a").count())) fail("no download link");
  await page.waitForTimeout(300);
  const png = await page.locator("#view").screenshot();
  writeFileSync(shot, png);
  await page.screenshot({ path: shot.replace(/\.png$/, "-page.png") });
  const img = decodePng(png);
  const bg = [29, 33, 39];
  let lit = 0, orange = 0;
  for (let i = 0; i < img.width * img.height; i++) {
    const p = img.data.subarray(i * img.channels, i * img.channels + 3);
    if (Math.abs(p[0] - bg[0]) + Math.abs(p[1] - bg[1]) + Math.abs(p[2] - bg[2]) > 30) lit++;
    if (p[0] > p[1] + 20 && p[1] > p[2]) orange++;
  }
  const total = img.width * img.height;
  console.log(`page: "${text}"; canvas ${img.width}x${img.height}: ${lit} non-background pixels (${(100 * lit / total).toFixed(1)} %), ${orange} mesh-coloured; screenshot ${shot}`);
  if (logs.some((l) => l.startsWith("[external request]") || l.startsWith("[pageerror]"))) fail(logs.join("\n"));
  if (lit < 0.02 * total || orange < 0.01 * total) fail("the canvas does not show the mesh");
  console.log("browser test passed");
} finally {
  await browser.close();
}
