# Written by vistream; redraw with: gnuplot latency_bandwidth_london.gp
set terminal pngcairo size 1100,900 enhanced font 'DejaVu Sans,12' linewidth 1.5
set output 'latency_bandwidth_london.png'
set encoding utf8
set multiplot layout 2,1 title 'london: stalls and arrival margin against link bandwidth (scheme pvs, 6 km/h)' font ',15'
set grid lc rgb '#d0d0d0'
set logscale x 2
set xtics ('0.0625' 0.0625, '0.125' 0.125, '0.25' 0.25, '0.5' 0.5, '1' 1, '2' 2, '4' 4)
set lmargin 12
set rmargin 25
set xlabel 'link bandwidth (Mbit/s, log scale)'
set key outside right top box
set title 'Stalled time (frames drawn before the PVS geometry of their viewcell arrived)'
set ylabel 'stalled time (% of the walk)'
set yrange [0:*]
plot 'latency_bandwidth_london.sweep.dat' using 1:2 with linespoints lw 2 pt 7 lc rgb '#d62728' title 'stalled time'
set title 'Arrival margin (time from a PVS completing to the client entering its cell)'
set ylabel 'margin (s)'
set yrange [*:*]
set key outside right top box
plot 'latency_bandwidth_london.sweep.dat' using 1:3 with linespoints lw 2 pt 7 lc rgb '#1f77b4' title 'minimum margin', 'latency_bandwidth_london.sweep.dat' using 1:4 with linespoints lw 2 pt 5 lc rgb '#2ca02c' title 'mean margin', 0 with lines lc rgb '#555555' dt 2 notitle
unset multiplot
