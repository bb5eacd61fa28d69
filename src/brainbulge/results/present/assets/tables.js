/* brainbulge report tables: a click on a column's header sorts the rows by it (numbers as
 * numbers, the rest as text; a second click reverses the order). */
(function () {
  "use strict";
  function key(cell) {
    var t = cell.textContent.trim(), x = parseFloat(t);
    return isNaN(x) || !/^[-+]?[\d.]/.test(t) ? [1, t.toLowerCase()] : [0, x];
  }
  Array.prototype.forEach.call(document.querySelectorAll("table.sortable"), function (table) {
    var body = table.tBodies[0];
    if (!body || !table.tHead) return;
    Array.prototype.forEach.call(table.tHead.rows[0].cells, function (th, col) {
      th.title = "sort by this column";
      th.addEventListener("click", function () {
        var dir = th.getAttribute("data-sort") === "asc" ? -1 : 1;
        Array.prototype.forEach.call(table.tHead.rows[0].cells, function (o) { o.removeAttribute("data-sort"); });
        th.setAttribute("data-sort", dir > 0 ? "asc" : "desc");
        var rows = Array.prototype.slice.call(body.rows);
        rows.sort(function (a, b) {
          var ka = key(a.cells[col] || a.cells[0]), kb = key(b.cells[col] || b.cells[0]);
          if (ka[0] !== kb[0]) return ka[0] - kb[0];
          return (ka[1] < kb[1] ? -1 : ka[1] > kb[1] ? 1 : 0) * dir;
        });
        rows.forEach(function (r) { body.appendChild(r); });
      });
    });
  });
})();
