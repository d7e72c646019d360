// Screenshots of the operator layout in Lichtblick (built from source), driven headless with
// puppeteer-core. A by-hand step, not a test: docs/recording.md ("Screenshots in Lichtblick")
// says how to build the app and start the stack; docs/screenshots/take.sh does both ends.
//
//   node take.js --app http://127.0.0.1:28080/ --ws ws://127.0.0.1:28765 \
//     --layout config/foxglove/thrusterd-live.json --out docs/screenshots \
//     --sim-pid PID --ctl target/release/thrusterctl --namespace NS
//
// For each window size (1366x768, 1920x1080) in a fresh browser profile: open the app on the
// bridge (`?ds=foxglove-websocket&ds.url=...`), import the layout through the app's own menu
// (View > Import layout from file...; the OS file picker is the one thing replaced, by a
// stub handing over the layout file), press the layout's Estimate button, wait for the model
// (thrusterctl status --json), press Hold, screenshot `holding-WxH.png`; then stop the
// simulator (SIGSTOP: no IMU sample, the daemon faults), press Hold again (refused in fault),
// screenshot `fault-WxH.png`, resume the simulator (SIGCONT) and wait for the daemon to hold
// again.
"use strict";

const fs = require("fs");
const path = require("path");
const { execFileSync } = require("child_process");
const puppeteer = require("puppeteer-core");

function arg(name, fallback) {
  const i = process.argv.indexOf(`--${name}`);
  if (i >= 0 && i + 1 < process.argv.length) {
    return process.argv[i + 1];
  }
  if (fallback === undefined) {
    throw new Error(`--${name} is required`);
  }
  return fallback;
}

const APP = arg("app");
const WS = arg("ws");
const LAYOUT = arg("layout");
const OUT = arg("out");
const SIM_PID = Number(arg("sim-pid"));
const CTL = arg("ctl");
const NS = arg("namespace");
const CHROMIUM = arg("chromium", "/usr/bin/chromium");
const SIZES = arg("sizes", "1366x768,1920x1080").split(",");
const PREFIX = arg("prefix", "");

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
const log = (...a) => console.error(new Date().toISOString().slice(11, 19), ...a);

function status() {
  const out = execFileSync(CTL, ["--namespace", NS, "status", "--json"], {
    encoding: "utf8",
    timeout: 10000,
  });
  return JSON.parse(out);
}

async function waitFor(what, pred, timeoutMs) {
  const end = Date.now() + timeoutMs;
  let last;
  while (Date.now() < end) {
    try {
      last = status();
      if (pred(last)) {
        return last;
      }
    } catch (e) {
      last = String(e);
    }
    await sleep(500);
  }
  throw new Error(`timed out waiting for ${what}: ${JSON.stringify(last)}`);
}

// The CallService button of the layout whose text is `text`.
async function button(page, text) {
  const handles = await page.$$('[data-testid="call-service-button"]');
  for (const h of handles) {
    const t = await h.evaluate((el) => el.innerText.trim());
    if (t === text) {
      return h;
    }
  }
  throw new Error(`no button "${text}"`);
}

// Pressed as an operator would: at its centre, and only if that point shows the button (a
// button clipped by a panel too small for it is not pressed).
async function press(page, text) {
  const b = await button(page, text);
  const visible = await b.evaluate((el) => {
    const r = el.getBoundingClientRect();
    const hit = document.elementFromPoint(r.x + r.width / 2, r.y + r.height / 2);
    return r.width > 0 && r.height > 0 && hit != undefined && el.contains(hit);
  });
  if (!visible) {
    throw new Error(`button "${text}" is not visible at ${page.viewport().width}x${page.viewport().height}`);
  }
  await b.click();
  log(`pressed ${text}`);
  // The mouse off the button, so its tooltip does not cover the panels.
  await page.mouse.move(page.viewport().width / 2, 20);
  await sleep(1500);
}

// The service panels' Response boxes that hold something, for the log.
async function responses(page) {
  return await page.$$eval('textarea:not([aria-hidden="true"])', (tas) =>
    tas.map((t) => t.value).filter((v) => v && v.length > 0 && v.includes("\n")),
  );
}

async function shot(page, name) {
  const file = path.join(OUT, `${PREFIX}${name}.png`);
  await page.screenshot({ path: file });
  log(`wrote ${file} (${fs.statSync(file).size} bytes)`);
}

async function importLayout(page) {
  await page.waitForSelector('[data-testid="AppMenuButton"]', { timeout: 120000 });
  await sleep(2000);
  await page.click('[data-testid="AppMenuButton"]');
  await page.waitForSelector("#app-menu-view", { visible: true });
  await page.hover("#app-menu-view");
  const item = await page.waitForSelector("::-p-text(Import layout from file)", {
    visible: true,
  });
  await item.click();
  // The imported layout is selected at once; its panels carry our titles.
  await page.waitForSelector('[data-testid="call-service-button"]', { timeout: 30000 });
  log("layout imported");
  // The app opens with its left sidebar (panel settings, topics); an operator closes it.
  const hide = await page.$('[data-testid="left-sidebar-button"][aria-label*="Hide"]');
  if (hide) {
    await hide.click();
    await page.mouse.move(page.viewport().width / 2, 20);
    log("left sidebar closed");
  }
}

async function run(browser, size, layoutText) {
  const [w, h] = size.split("x").map(Number);
  const context = await browser.createBrowserContext();
  const page = await context.newPage();
  page.on("pageerror", (e) => log(`page error: ${e.message}`));
  await page.setViewport({ width: w, height: h });
  await page.evaluateOnNewDocument((text) => {
    // The OS file dialog, replaced: the app's import reads this file through its own code.
    window.showOpenFilePicker = async () => [
      {
        kind: "file",
        name: "thrusterd-live.json",
        getFile: async () =>
          new File([text], "thrusterd-live.json", { type: "application/json" }),
      },
    ];
  }, layoutText);
  const url = `${APP}?ds=foxglove-websocket&ds.url=${encodeURIComponent(WS)}`;
  log(`${size}: ${url}`);
  await page.goto(url, { waitUntil: "networkidle2", timeout: 120000 });
  await importLayout(page);
  await sleep(3000);
  await shot(page, `connected-${size}`);

  // An estimation from the layout's button, then Hold from its button.
  const before = status();
  log(`state ${before.state}, model ${before.model_version}`);
  let done;
  for (let attempt = 1; ; attempt++) {
    await press(page, "Estimate");
    const end = await waitFor(
      "the estimation's end",
      (s) => s.model_version > before.model_version || s.state === "Idle",
      120000,
    );
    if (end.model_version > before.model_version) {
      done = await waitFor("holding", (s) => s.state === "Active", 60000);
      break;
    }
    // Refused by the daemon (its reason is in the status text): pictured, and tried again.
    log(`estimation ${attempt} gave no model: ${end.text}`);
    await sleep(1000);
    await shot(page, `no-model-${attempt}-${size}`);
    if (attempt === 3) {
      throw new Error("no model after 3 estimations");
    }
  }
  log(`model ${done.model_version}, state ${done.state}: ${done.text}`);
  await press(page, "Hold");
  // 20 s of holding in the plots' 30 s window.
  await sleep(20000);
  log(`responses: ${JSON.stringify(await responses(page))}`);
  await shot(page, `holding-${size}`);

  // A fault: the simulator stopped, no IMU sample for the daemon's deadline.
  process.kill(SIM_PID, "SIGSTOP");
  try {
    await waitFor("fault", (s) => s.state === "Fault", 20000);
    await sleep(1000);
    await press(page, "Hold");
    await sleep(1500);
    log(`responses: ${JSON.stringify(await responses(page))}`);
    await shot(page, `fault-${size}`);
  } finally {
    process.kill(SIM_PID, "SIGCONT");
  }
  await waitFor("active again", (s) => s.state === "Active", 30000);
  await context.close();
}

async function main() {
  const layoutText = fs.readFileSync(LAYOUT, "utf8");
  fs.mkdirSync(OUT, { recursive: true });
  const browser = await puppeteer.launch({
    executablePath: CHROMIUM,
    headless: true,
    args: ["--no-sandbox", "--disable-dev-shm-usage", "--use-angle=swiftshader"],
  });
  try {
    log(`chromium ${await browser.version()}`);
    for (const size of SIZES) {
      await run(browser, size, layoutText);
    }
  } finally {
    await browser.close();
  }
}

main().catch((e) => {
  console.error(e);
  process.exit(1);
});
