# Written by vistream; redraw with: gnuplot table1_london.gp
set terminal pngcairo size 1200,1000 enhanced font 'DejaVu Sans,12' linewidth 1.5
set output 'table1_london.png'
set encoding utf8
set multiplot layout 2,1 title 'Dual ray space on london: time and overestimation by raster resolution' font ',15'
set grid lc rgb '#d0d0d0'
set logscale x 2
set xtics (1, 2, 4, 8, 16, 32, 64, 128, 256)
set xrange [12.8:320]
set xlabel 'raster resolution (pixels per side of the dual ray space, log scale)'
set key outside right box
set logscale y 10
set title 'Time per viewcell'
set ylabel 'time per viewcell (ms, log scale)'
plot 'table1_london.series0.dat' using 1:2 with linespoints lw 2 pt 7 title '50 m, cpu', 'table1_london.series1.dat' using 1:2 with linespoints lw 2 pt 7 title '50 m, gl', 'table1_london.series2.dat' using 1:2 with linespoints lw 2 pt 7 title '100 m, cpu', 'table1_london.series3.dat' using 1:2 with linespoints lw 2 pt 7 title '100 m, gl', 'table1_london.series4.dat' using 1:2 with linespoints lw 2 pt 7 title '300 m, cpu', 'table1_london.series5.dat' using 1:2 with linespoints lw 2 pt 7 title '300 m, gl'
set title 'Overestimation (points at 0 are left out of the log scale)'
set ylabel 'overestimation (% of occluded area, log scale)'
plot 'table1_london.series0.dat' using 1:($3 > 0 ? $3 : NaN) with linespoints lw 2 pt 7 title '50 m, cpu', 'table1_london.series1.dat' using 1:($3 > 0 ? $3 : NaN) with linespoints lw 2 pt 7 title '50 m, gl', 'table1_london.series2.dat' using 1:($3 > 0 ? $3 : NaN) with linespoints lw 2 pt 7 title '100 m, cpu', 'table1_london.series3.dat' using 1:($3 > 0 ? $3 : NaN) with linespoints lw 2 pt 7 title '100 m, gl', 'table1_london.series4.dat' using 1:($3 > 0 ? $3 : NaN) with linespoints lw 2 pt 7 title '300 m, cpu', 'table1_london.series5.dat' using 1:($3 > 0 ? $3 : NaN) with linespoints lw 2 pt 7 title '300 m, gl'
unset multiplot
