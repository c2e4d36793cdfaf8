// lidarfield's study overview: the ranked pairs table sorted by a click on a column's header
// (again: the other way) and filtered by the words typed in its box. Plain DOM, no library.
(function () {
  "use strict";

  // A cell's sort key: its number when the text is one ("12.5", "3.1%"), else its text.
  function key(cell) {
    const text = cell.textContent.trim();
    const number = parseFloat(text.replace(/[,%]/g, ""));
    return text === "" ? null : Number.isFinite(number) && /^[-+0-9.,e%\s]+$/i.test(text) ? number : text.toLowerCase();
  }

  function compare(a, b) {
    if (a === null || b === null) return a === null ? (b === null ? 0 : 1) : -1; // empty cells last
    if (typeof a === typeof b) return a < b ? -1 : a > b ? 1 : 0;
    return typeof a === "number" ? -1 : 1;
  }

  function sortable(table) {
    const heads = [...table.tHead.rows[0].cells], body = table.tBodies[0];
    heads.forEach((th, column) =>
      th.addEventListener("click", () => {
        const ascending = !th.classList.contains("asc");
        heads.forEach(h => h.classList.remove("asc", "desc"));
        th.classList.add(ascending ? "asc" : "desc");
        const rows = [...body.rows].map(row => [key(row.cells[column]), row]);
        // empty cells last whichever the direction
        rows.sort((p, q) => (p[0] === null || q[0] === null ? 1 : ascending ? 1 : -1) * compare(p[0], q[0]));
        for (const [, row] of rows) body.appendChild(row);
      })
    );
  }

  function filtered(table, input, count) {
    const apply = () => {
      const words = input.value.toLowerCase().split(/\s+/).filter(Boolean);
      let shown = 0;
      for (const row of table.tBodies[0].rows) {
        const text = row.textContent.toLowerCase();
        const keep = words.every(w => text.includes(w));
        row.hidden = !keep;
        shown += keep;
      }
      count.textContent = words.length ? `${shown} of ${table.tBodies[0].rows.length} pairs shown` : "";
    };
    input.addEventListener("input", apply);
  }

  document.addEventListener("DOMContentLoaded", () => {
    for (const table of document.querySelectorAll("table.sortable")) {
      sortable(table);
      const box = table.closest(".table-box"), filter = box && box.previousElementSibling;
      if (filter && filter.classList.contains("table-filter"))
        filtered(table, filter.querySelector("input.filter"), filter.querySelector(".filter-count"));
    }
    document.documentElement.dataset.readyMs = performance.now().toFixed(0); // open to interactive (bench/explorer.py)
    document.documentElement.dataset.overviewReady = "1";
  });
})();
