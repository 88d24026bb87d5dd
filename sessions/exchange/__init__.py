"""Sessions and results leaving or entering the catalog: bundles (export, import, manifest, signing),
imported data sets (JIGSAWS, bench video), xAPI statements and the LRS that receives them, and the
progress table (CSV/XLSX)."""
