from django.urls import path

from racing import views

app_name = "racing"
urlpatterns = [
    path("races/", views.race_list, name="race-list"),
    path("leaderboards/", views.leaderboard_list, name="leaderboard-list"),
    path("leaderboards/<slug:slug>/", views.leaderboard, name="leaderboard"),
]
