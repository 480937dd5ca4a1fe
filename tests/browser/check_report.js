// Injected at the end of Snakemake's report (tests/test_workflow.py, test_report_in_a_browser): once the
// page has loaded, checks what a reader's browser shows and writes the findings as JSON into
// <pre id="pbmdem-check"> for `chromium --dump-dom`:
//  - every <img> of the landing page (the workflow description with the findings) has loaded,
//  - every image result of the report decodes (naturalWidth > 0),
//  - every HTML result (the display tables), laid out WIDTH px wide, has no table
//    wider than the page and no image that failed to load.
(function () {
  const WIDTH = 1000;
  const out = { landing_images: 0, landing_alts: [], landing_broken: [], images: 0, broken: [], pages: 0, overflow: [], page_broken: [], errors: [] };
  function decoded(src) {
    return new Promise((resolve) => {
      const img = new Image();
      img.onload = () => resolve(img.naturalWidth > 0);
      img.onerror = () => resolve(false);
      img.src = src;
    });
  }
  function laidOut(name, html) {
    return new Promise((resolve) => {
      const frame = document.createElement("iframe");
      frame.style.width = WIDTH + "px";
      frame.style.height = "800px";
      frame.onload = () => {
        try {
          const doc = frame.contentDocument;
          const page = doc.documentElement.clientWidth;
          doc.querySelectorAll("table").forEach((t, k) => {
            const right = t.getBoundingClientRect().right;
            if (right > page + 1) out.overflow.push(`${name}: table ${k} ends at ${Math.round(right)} px of ${page}`);
          });
          doc.querySelectorAll("img").forEach((img, k) => {
            if (!(img.complete && img.naturalWidth > 0)) out.page_broken.push(`${name}: image ${k} (${img.alt})`);
          });
        } catch (e) {
          out.errors.push(`${name}: ${e}`);
        }
        frame.remove();
        resolve();
      };
      frame.srcdoc = html;
      document.body.appendChild(frame);
    });
  }
  function text(uri) {
    const comma = uri.indexOf(",");
    const head = uri.slice(0, comma);
    const body = uri.slice(comma + 1);
    const bytes = head.includes(";base64") ? Uint8Array.from(atob(body), (c) => c.charCodeAt(0)) : new TextEncoder().encode(decodeURIComponent(body));
    return new TextDecoder("utf-8").decode(bytes);
  }
  async function run() {
    const title = document.querySelector("h1.title");
    out.title_top = title ? Math.round(title.getBoundingClientRect().top) : null;
    document.querySelectorAll("img").forEach((img) => {
      out.landing_images += 1;
      out.landing_alts.push(img.alt || "");
      if (!(img.complete && img.naturalWidth > 0)) out.landing_broken.push(img.alt || img.src.slice(0, 60));
    });
    for (const [path, res] of Object.entries(results)) {
      if (res.mime_type.startsWith("image/")) {
        out.images += 1;
        if (!(await decoded(res.data_uri))) out.broken.push(path);
      } else if (res.mime_type === "text/html") {
        out.pages += 1;
        await laidOut(path, text(res.data_uri));
      }
    }
    const pre = document.createElement("pre");
    pre.id = "pbmdem-check";
    pre.textContent = JSON.stringify(out);
    document.body.appendChild(pre);
  }
  window.addEventListener("load", () => setTimeout(() => run().catch((e) => {
    out.errors.push(String(e));
    const pre = document.createElement("pre");
    pre.id = "pbmdem-check";
    pre.textContent = JSON.stringify(out);
    document.body.appendChild(pre);
  }), 500));
})();
