// Sortable tables: a click on a column's heading sorts the rows by it (numbers as numbers, dates
// and text as text), a second click reverses; the heading carries aria-sort for screen readers.
"use strict";

function cellValue(row, index) {
  const cell = row.children[index];
  const text = cell ? (cell.dataset.sort || cell.textContent).trim() : "";
  const number = parseFloat(text.replace(/[^0-9.+-eE]/g, ""));
  return { text: text, number: /^[-+]?[0-9.]/.test(text) && !/^\d{4}-\d\d-\d\d/.test(text) ? number : NaN };
}

function sortBy(table, index, heading) {
  const body = table.tBodies[0];
  const rows = Array.from(body.rows);
  const ascending = heading.getAttribute("aria-sort") !== "ascending";
  const numeric = rows.every((row) => !isNaN(cellValue(row, index).number) || cellValue(row, index).text === "");
  rows.sort((a, b) => {
    const x = cellValue(a, index), y = cellValue(b, index);
    const order = numeric ? (x.number || 0) - (y.number || 0) : x.text.localeCompare(y.text, undefined, { numeric: true });
    return ascending ? order : -order;
  });
  rows.forEach((row) => body.appendChild(row));
  table.querySelectorAll("th").forEach((th) => th.removeAttribute("aria-sort"));
  heading.setAttribute("aria-sort", ascending ? "ascending" : "descending");
}

document.addEventListener("DOMContentLoaded", () => {
  document.querySelectorAll("table.sortable").forEach((table) => {
    table.querySelectorAll("thead th").forEach((heading, index) => {
      heading.tabIndex = 0;
      heading.title = "sort by " + heading.textContent.trim();
      heading.addEventListener("click", () => sortBy(table, index, heading));
      heading.addEventListener("keydown", (event) => {
        if (event.key === "Enter" || event.key === " ") { event.preventDefault(); sortBy(table, index, heading); }
      });
    });
  });
});
