"""The report's one stylesheet, inlined in every page: screen and print (A4, plots three to a
row, sections not split across pages, no navigation)."""

CSS = """
:root { --ink: #1b1b1b; --muted: #666; --rule: #d0d0d0; --band: #f4f4f4; }
* { box-sizing: border-box; }
body { font: 14px/1.4 system-ui, -apple-system, "Segoe UI", Roboto, "DejaVu Sans", sans-serif;
       color: var(--ink); margin: 0 auto; max-width: 1100px; padding: 16px 20px 40px; }
header { border-bottom: 2px solid var(--ink); margin-bottom: 12px; }
header h1 { font-size: 22px; margin: 0 0 4px; }
header p { margin: 0 0 8px; color: var(--muted); }
nav { font-size: 13px; margin: 6px 0 10px; }
nav a, nav strong { margin-right: 12px; }
h2 { font-size: 17px; border-bottom: 1px solid var(--rule); padding-bottom: 2px;
     margin: 22px 0 8px; }
h3 { font-size: 14px; margin: 12px 0 6px; }
dl.facts { display: grid; grid-template-columns: max-content 1fr; gap: 2px 14px; margin: 0; }
dl.facts dt { color: var(--muted); }
dl.facts dd { margin: 0; }
.plots { display: grid; grid-template-columns: repeat(auto-fill, minmax(300px, 1fr));
         gap: 6px 10px; }
svg.plot { width: 100%; height: auto; display: block; }
svg.plot .title { font-size: 11px; font-weight: 600; text-anchor: middle; }
svg.plot .tick, svg.plot .legend { font-size: 8px; fill: #444; }
svg.plot .axis { font-size: 8.5px; fill: #444; }
svg.plot .empty { font-size: 10px; fill: var(--muted); }
svg.plot .grid { stroke: #e3e3e3; stroke-width: 0.6; }
svg.plot .zero { stroke: #9a9a9a; stroke-width: 0.8; }
svg.plot .frame { fill: none; stroke: #9a9a9a; stroke-width: 0.8; }
svg.plot .norm { opacity: 0.28; }
svg.plot .sd { opacity: 0.18; }
svg.plot .mean { fill: none; stroke-width: 1.6; }
svg.plot .toe-off { stroke-width: 0.9; stroke-dasharray: 3 2; }
table { border-collapse: collapse; margin: 4px 0 10px; font-size: 13px; }
th, td { border-bottom: 1px solid var(--rule); padding: 3px 9px; text-align: right;
         vertical-align: top; }
th:first-child, td:first-child { text-align: left; }
thead th { border-bottom: 1.5px solid var(--ink); font-weight: 600; }
tbody tr:nth-child(even) { background: var(--band); }
td.text { text-align: left; }
.bad { color: #b00020; font-weight: 600; }
.note { color: var(--muted); font-size: 12.5px; }
pre { background: var(--band); padding: 8px; overflow-x: auto; font-size: 12px; }
footer { margin-top: 28px; color: var(--muted); font-size: 12px; }
@page { size: A4; margin: 12mm; }
@media print {
  body { max-width: none; padding: 0; font-size: 10.5pt; }
  nav { display: none; }
  a { color: inherit; text-decoration: none; }
  .plots { grid-template-columns: repeat(3, 1fr); }
  section, table, svg.plot { break-inside: avoid; }
  h2 { break-after: avoid; }
  tbody tr:nth-child(even) { background: none; }
  pre { white-space: pre-wrap; }
}
"""
