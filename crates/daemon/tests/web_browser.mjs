// Headless Chromium on the lightpose page, as BlueOS shows it (under a
// path prefix, through a proxy): it must draw the heatmap, change the
// pose at least 5 times a second, say `ok`, throw no script error; after
// the daemon restarts (the Rust side restarts it with the mock backend's
// faults, between the two lines on stdin/stdout) it must reconnect by
// itself and say what is wrong. Prints one JSON object; the Rust test
// judges it. Screenshots go to SHOTS_DIR.
//
// usage: node web_browser.mjs NODE_MODULES URL SHOTS_DIR
import { createRequire } from "node:module";
import readline from "node:readline";
import path from "node:path";

const [nodeModules, url, shots] = process.argv.slice(2);
const require = createRequire(path.join(nodeModules, "x.js"));
const { chromium } = require("playwright-core");

const lines = readline.createInterface({ input: process.stdin });
const nextLine = () => new Promise((res) => lines.once("line", res));
const sleep = (ms) => new Promise((res) => setTimeout(res, ms));

const browser = await chromium.launch({
  executablePath: "/usr/bin/chromium",
  headless: true,
  args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking"],
});
const out = { scriptErrors: [], consoleErrors: [] };
try {
  // A tablet's screen.
  const page = await browser.newPage({ viewport: { width: 1024, height: 1366 } });
  page.on("pageerror", (e) => out.scriptErrors.push(String(e)));
  let phase = "live";
  page.on("console", (m) => {
    if (m.type() === "error" && phase === "live") out.consoleErrors.push(m.text());
  });
  const requests = [];
  page.on("request", (r) => requests.push(r.url()));
  await page.goto(url, { waitUntil: "load" });
  await page.waitForFunction(() => window.lightpose && window.lightpose.live >= 3, null, { timeout: 20000 });
  await page.waitForFunction(() => document.getElementById("status").textContent === "ok", null, { timeout: 20000 });

  // Two seconds of the feed: events, and the pose text as a person sees it.
  const n0 = await page.evaluate(() => window.lightpose.live);
  const xs = new Set();
  const t0 = Date.now();
  while (Date.now() - t0 < 2000) {
    xs.add(await page.textContent("#p-x"));
    await sleep(50);
  }
  const n1 = await page.evaluate(() => window.lightpose.live);
  out.rate = (n1 - n0) / ((Date.now() - t0) / 1000);
  out.distinctX = xs.size;
  out.heatmap = await page.evaluate(() => {
    const c = document.querySelector("canvas.heatmap");
    const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
    const colours = new Set();
    for (let i = 0; i < d.length; i += 4 * 97) colours.add(`${d[i]},${d[i + 1]},${d[i + 2]}`);
    return { drawn: Number(c.dataset.drawn), colours: colours.size };
  });
  out.trackPoints = await page.evaluate(() => Number(document.getElementById("top").dataset.points));
  out.status = await page.textContent("#status");
  out.estimatorTable = await page.textContent("#estimator");
  out.readingsTable = await page.textContent("#readings");
  out.counters = await page.textContent("#counters");
  out.requests = requests;
  await page.screenshot({ path: path.join(shots, "web-ok.png"), fullPage: true });

  // The daemon restarts, now with faults: the page reconnects by itself.
  phase = "restart";
  console.log("RESTART");
  await nextLine();
  await page.waitForFunction(() => window.lightpose.connects >= 2, null, { timeout: 30000 });
  const m0 = await page.evaluate(() => window.lightpose.live);
  await page.waitForFunction((m) => window.lightpose.live > m + 3, m0, { timeout: 20000 });
  await page.waitForFunction(
    () => document.getElementById("status").textContent !== "ok" && !document.getElementById("why").hidden,
    null,
    { timeout: 20000 },
  );
  // A STATUS or two more, so that the reasons have the faults' counts.
  await sleep(1500);
  out.connects = await page.evaluate(() => window.lightpose.connects);
  out.faultStatus = await page.textContent("#status");
  out.why = await page.textContent("#why");
  await page.screenshot({ path: path.join(shots, "web-fault.png"), fullPage: true });
  out.pageErrors = await page.evaluate(() => window.lightpose.errors);
} finally {
  await browser.close();
}
console.log(JSON.stringify(out));
process.exit(0);
